"""What one training update is, for a reader and for a refactor:
`python -m benchmarks.trace_update --methods a3c+foresit a3c+maml+foresit`.

For each method (at a preset's sizes, tiny by default):

* the functions of `foresit_jax` that lowering one `Trainer.update` runs through, per file,
  counted in lines (each outermost function once; nested ones are inside it): what a reader
  crosses to follow one update;
* the project's files (experiments/, foresit_jax/, envs/) from the CLI's entry (`python -m
  experiments.train --method M --preset P`) to the first update's `optax.apply_updates`
  (`files_from_cli`; `--cli-path`): every file that runs, and the reader's path (the call
  chain to the optimiser, then the update's body; `CliPath`);
* a short sha256 of each lowered program: a chunk of training (`Trainer.run`), the
  evaluation rollout (`Evaluator.agent_rollout`) and the sub-goal collection
  (`train.collect_subgoal_items`). Equal hashes before and after a refactor mean the
  same compiled program (the lowered text carries no source locations), so no speed or
  numbers can have changed; run it at both commits (`PYTHONPATH=<checkout>`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import functools
import os
import runpy
import sys
import tempfile
import threading
import warnings

import jax
import jax.numpy as jnp
import tyro

import experiments
import foresit_jax
from experiments.running.presets import preset
from foresit_jax.evaluate import Evaluator
from foresit_jax.methods import parse_method
from foresit_jax.rollout import AgentParams
from foresit_jax.train import collect_subgoal_items, make_trainer


@dataclasses.dataclass(frozen=True)
class Args:
    """The training path of methods, and their lowered programs' hashes."""

    methods: tuple[str, ...] = ("a3c", "a3c+foresit")
    """methods (see foresit_jax.methods); the object-graph ones run on the org setup"""
    preset: str = "tiny"
    """preset giving the sizes (the path and the hashes depend on the sizes only through shapes)"""
    cli_path: bool = False
    """also count the project files from `python -m experiments.train`'s entry to the optax update (trains one
    tiny run per method in a temporary folder: about a minute each)"""


def _short(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def functions_crossed(fn, *args) -> dict[str, tuple[int, int]]:
    """{file name: (functions, lines)} of `foresit_jax`'s functions that lowering
    `jax.jit(fn)(*args)` calls, each outermost function counted once."""
    root = os.path.dirname(foresit_jax.__file__)
    seen = {}

    def tracer(frame, event, arg):
        if event == "call" and frame.f_code.co_filename.startswith(root):
            seen[(frame.f_code.co_filename, frame.f_code.co_firstlineno)] = frame.f_code
        return None

    sys.settrace(tracer)
    try:
        jax.jit(fn).lower(*args)
    finally:
        sys.settrace(None)
    spans = {}
    for (path, _), code in seen.items():
        try:
            lines, start = inspect.getsourcelines(code)
        except OSError:  # generated code (dataclass methods): no source to read
            continue
        spans.setdefault(os.path.basename(path), []).append((start, start + len(lines) - 1))
    out = {}
    for name, found in sorted(spans.items()):
        outer = []
        for a, b in sorted(found):
            if outer and b <= outer[-1][1]:
                continue  # inside the previous one
            outer.append((a, b))
        out[name] = (len(outer), sum(b - a + 1 for a, b in outer))
    return out


@dataclasses.dataclass(frozen=True)
class CliPath:
    """The project's files (paths under the checkout: experiments/, foresit_jax/, envs/)
    from `python -m experiments.train`'s entry to the first `optax.apply_updates`.

    entered: every file whose functions run before that call (a module's import-time code
      and a package's lazy `__getattr__` not counted), in the order first entered: the
      setup too (the run folder, the scene banks, the checkpointer).
    reader: what a reader follows to learn what one update is: the files on the call stack
      at that call, outermost first (the command, the run loop, the Trainer), then those
      entered from the first `Trainer.update` until the call (the update's body: acting,
      the environment's step, the networks, the loss), each once. Issue 60 counted 17 this
      way before the redesign (this count gives 16 at f511043).
    config: what a reader needs besides to know what the Config says, not already on the
      reader's path: the files on the call stack wherever a `Config` is made (its
      `__post_init__`, before the first update: the command's flags, the preset, the
      method's defaults), and those its making enters (the method's parser).
    Issue 70 counts `reader` and `config` together, for a3c+foresit."""

    entered: list[str]
    reader: list[str]
    config: list[str] = dataclasses.field(default_factory=list)

    @property
    def to_read(self) -> list[str]:
        """The reader's path and the Config's sources, each once."""
        return self.reader + self.config


def files_from_cli(method: str, preset: str = "tiny") -> CliPath:
    """Runs `python -m experiments.train --method M --preset P` in a temporary folder and
    records its `CliPath` (what runs after the first `optax.apply_updates` is not counted)."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(experiments.__file__)))
    packages = tuple(os.path.join(root, p) + os.sep for p in ("experiments", "foresit_jax", "envs"))
    update_file = os.path.join(root, "foresit_jax", "train.py")
    config_file = os.path.join(root, "foresit_jax", "config.py")
    entered: list[str] = []
    body: list[str] = []
    stack: list[str] = []
    config: list[str] = []  # the Config's sources: the stacks that make a Config, and what its making enters
    state = {"on": True, "in_update": False, "in_config": 0}

    def project_stack(frame) -> list[str]:
        files = []
        while frame is not None:
            file = frame.f_code.co_filename
            if file.startswith(packages) and os.path.relpath(file, root) not in files:
                files.append(os.path.relpath(file, root))
            frame = frame.f_back
        return files[::-1]  # outermost first

    def leaving_config(frame, event, arg):
        if event == "return":
            state["in_config"] -= 1
        return leaving_config

    def tracer(frame, event, arg):
        if not state["on"] or event != "call":
            return None
        path, name = frame.f_code.co_filename, frame.f_code.co_name
        if name == "apply_updates" and f"{os.sep}optax{os.sep}" in path:
            state["on"] = False
            stack.extend(project_stack(frame.f_back)[::-1])
        elif name not in ("<module>", "__getattr__") and path.startswith(packages):
            file = os.path.relpath(path, root)
            state["in_update"] |= name == "update" and path == update_file
            if not state["in_update"] and name == "__post_init__" and path == config_file:
                if file not in entered:
                    entered.append(file)
                config.extend(f for f in project_stack(frame) if f not in config)
                state["in_config"] += 1
                return leaving_config
            seen_by = [entered, body] if state["in_update"] else [entered]
            if state["in_config"]:
                seen_by.append(config)
            for seen in seen_by:
                if file not in seen:
                    seen.append(file)
        return None

    with tempfile.TemporaryDirectory() as out:
        argv = sys.argv
        sys.argv = [
            "experiments.train",
            "--method",
            method,
            "--preset",
            preset,
            "--out",
            os.path.join(out, "run"),
            "--no-progress",
        ]
        sys.settrace(tracer)
        threading.settrace(tracer)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                runpy.run_module("experiments.train", run_name="__main__", alter_sys=True)
        finally:
            sys.settrace(None)
            threading.settrace(None)
            sys.argv = argv
    reader = list(dict.fromkeys(stack[::-1] + body))
    return CliPath(entered, reader, [f for f in config if f not in reader])


def acting_depth(trainer, state, modules: tuple[str, ...] = ("rollout.py", "imagination.py")) -> list[str]:
    """The deepest chain of `modules`' functions (acting's: rollout.py, and imagination.py,
    where i_tau is made since 0.4.0) below `act_window` while one training window is
    lowered, outermost first (`act_window`'s scan body first): what a reader follows down
    one acting step. Tracing runs every branch of `lax.cond` and
    `lax.switch`, so a branch's calls count; lambdas and comprehensions do not (a reader
    does not leave the line for them)."""
    deepest: list[str] = []

    def tracer(frame, event, arg):
        if event != "call" or not frame.f_code.co_filename.endswith(modules) or frame.f_code.co_name.startswith("<"):
            return None
        chain, f = [], frame
        while f is not None and f.f_code.co_name != "act_window":
            if f.f_code.co_filename.endswith(modules) and not f.f_code.co_name.startswith("<"):
                chain.append(f.f_code.co_name)
            f = f.f_back
        if f is not None and len(chain) > len(deepest):
            deepest[:] = chain[::-1]
        return None

    env = trainer.bind(trainer.env_params)
    window = functools.partial(trainer.act, env=env)
    sys.settrace(tracer)
    try:
        jax.jit(window).lower(AgentParams(state.params, state.imagination_params), actor=state.actor, key=state.key)
    finally:
        sys.settrace(None)
    return deepest


def program_hashes(trainer, state) -> dict[str, str]:
    """Short hashes of the lowered training chunk (2 updates), evaluation rollout and
    sub-goal collection (2 windows) of `trainer` from `state`."""
    config = trainer.config
    train = jax.jit(trainer.run, static_argnums=2).lower(state, trainer.env_params, 2).as_text()
    evaluator = Evaluator.for_config(config)
    rollout = evaluator.agent_rollout(config, 30, config.pieces.greedy_evaluation)
    room = evaluator.room_params("val", (config.room_types or ("bathroom",))[0])
    evaluate = rollout.lower(
        state.params, state.imagination_params, room, jax.random.PRNGKey(1), jnp.zeros(8)
    ).as_text()
    subgoals = jax.jit(functools.partial(collect_subgoal_items, trainer), static_argnums=2)
    subgoals = subgoals.lower(state, trainer.env_params, 2).as_text()
    return {"train": _short(train), "evaluate": _short(evaluate), "subgoals": _short(subgoals)}


def main(args: Args) -> dict:
    report = {}
    for method in args.methods:
        setup = parse_method(method).encoder_piece.required_setup or "savn"
        config, _ = preset(args.preset, method, setup=setup)
        trainer = make_trainer(config)
        state = trainer.init(jax.random.PRNGKey(0))
        crossed = functions_crossed(trainer.update, state, trainer.env_params)
        report[method] = {"files": crossed, "hashes": program_hashes(trainer, state)}
        report[method]["acting_depth"] = acting_depth(trainer, state)
        functions = sum(f for f, _ in crossed.values())
        lines = sum(n for _, n in crossed.values())
        print(
            f"{method} ({args.preset}): one update crosses {functions} functions, {lines} lines, "
            f"in {len(crossed)} files of foresit_jax"
        )
        for name, (f, n) in crossed.items():
            print(f"  {name:18s} {f:3d} functions {n:5d} lines")
        depth = report[method]["acting_depth"]
        print(
            f"  one acting step: {len(depth)} calls of rollout.py and imagination.py deep below act_window ({' -> '.join(depth)})"
        )
        print("  lowered programs: " + ", ".join(f"{k} {v}" for k, v in report[method]["hashes"].items()))
        if args.cli_path:
            path = files_from_cli(method, args.preset)
            report[method]["cli_files"], report[method]["reader_files"] = path.entered, path.reader
            report[method]["config_files"] = path.config
            print(
                f"  from `python -m experiments.train` to optax.apply_updates: {len(path.entered)} project files "
                f"run; a reader follows {len(path.reader)} (the call chain, then the update): " + ", ".join(path.reader)
            )
            print(
                f"  and {len(path.config)} more to know what the Config says: "
                + ", ".join(path.config)
                + f" ({len(path.to_read)} in all)"
            )
    return report


if __name__ == "__main__":
    main(tyro.cli(Args))
