"""The project's own fuzz of bad input (issue 71): a table of flags, arm strings, damaged
run folders and unusable outputs, given to every program, and a hypothesis strategy over
flag values and folder damage.

Each case asserts what a user sees: the exit status; on stderr either one `error:` line or
tyro's framed message (for a value that does not parse), never a traceback; and the tree
under the test's folder exactly as it was (no run.json, no .lock, no empty checkpoints/).

The programs are called in-process (`cli(argv)`, SystemExit caught, stderr read with
capsys): every case here is refused before anything trains or compiles. Cases that need a
trained run (flipped checkpoint bytes, deleted checkpoints) and the same refusals through
a subprocess are in the slow tier (`test_fuzz_slow.py`).

Issue 80's four classes (below the line "issue 80's classes") are generated, not listed:
arms and flags that disagree or break a method's requirement, paths the OS refuses
(names too long, symbolic link loops, dangling links), values of the wrong type for a
Config field, and policies and states at the library's boundary (`evaluate_policy`,
`make_act`, `experiments.load`). Each class has a mutation check: with its fix undone
(monkeypatched to a no-op or to the code before it), the same generated cases fail.
"""

from __future__ import annotations

import dataclasses
import errno
import functools
import hashlib
import importlib
import json
import os
import typing
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, example, given, settings
from hypothesis import strategies as st

import train_helpers as H
from experiments.running import presets, sweeps
from experiments import rundir
from experiments.running.run import Run
from foresit_jax import config as config_module
from foresit_jax.config import Config, field_types
from foresit_jax.methods import GRADIENTS, ROLLOUTS, parse_method

PROGRAMS = ("train", "sweep", "tune", "paper", "evaluate", "compare", "probe", "failures", "cvae_compare", "foresight")
TOO_BIG = str(2**70)

# (program, argv, exit status). In argv: {out} a path not yet made; {file} a plain file;
# {ro} a read-only folder's child (root writes there: skipped); {under_file} a path under a
# plain file; {uni} a new path with spaces and unicode; {run} a
# started one-seed run (run.json only); {sweep} a started sweep (sweep.json only);
# {missing} a path that is not there.
FLAGS = [
    # train: numbers out of range, values that do not name anything, exclusive flags
    ("train", ["--seed", "-1"], 2),
    ("train", ["--seed", TOO_BIG], 2),
    ("train", ["--seed", "1.5"], 2),
    ("train", ["--num-lanes", "0"], 2),
    ("train", ["--num-lanes", "-4"], 2),
    ("train", ["--num-lanes", str(10**9)], 2),
    ("train", ["--num-updates", "0"], 2),
    ("train", ["--num-updates", "-5"], 2),
    ("train", ["--num-updates", str(10**20)], 2),
    ("train", ["--num-steps", "0"], 2),
    ("train", ["--hidden-size", "0"], 2),
    ("train", ["--buffer-size", "0"], 2),
    ("train", ["--learning-rate", "abc"], 2),
    ("train", ["--learning-rate", "-1"], 2),
    ("train", ["--learning-rate", "nan"], 2),
    ("train", ["--gamma", "1.5"], 2),
    ("train", ["--room-types", "attic"], 2),
    ("train", ["--room-types", "kitchen", "kitchen"], 2),
    ("train", ["--layout", "castle"], 2),
    ("train", ["--perception-range", "-1"], 2),
    ("train", ["--setup", "xyz"], 2),
    ("train", ["--preset", "huge"], 2),
    ("train", ["--method", "a3c+nothing"], 2),
    ("train", ["--method", ""], 2),
    ("train", ["--method", "a3c@"], 2),
    ("train", ["--method", "a3c@lr=3"], 2),
    ("train", ["--method", "a3c@learning_rate=abc"], 2),
    ("train", ["--method", "a3c@learning_rate"], 2),
    ("train", ["--method", "a3c@priors=true"], 2),
    ("train", ["--method", "a3c+org"], 2),  # the object graph needs --setup org
    ("train", ["--chunk-updates", "0"], 2),
    ("train", ["--test-episodes-per-room", "0"], 2),
    ("train", ["--val-episodes-per-room", "-1"], 2),
    ("train", ["--track", "bogus"], 2),
    ("train", ["--resume", "--overwrite"], 2),
    ("train", ["--unknown-flag", "1"], 2),
    # sweep: seeds, arms, reuse
    ("sweep", ["--seeds", "0"], 2),
    ("sweep", ["--seeds", "-1"], 2),
    ("sweep", ["--seeds", str(10**6)], 2),
    ("sweep", ["--seed", str(2**63 - 1), "--seeds", "2"], 2),
    ("sweep", ["--methods"], 2),
    ("sweep", ["--methods", "a3c", "a3c"], 2),
    ("sweep", ["--methods", "a3c", "bogus"], 2),
    ("sweep", ["--methods", "a3c@learning_rate=1e-3,learning_rate=x"], 2),
    ("sweep", ["--reuse", "{missing}"], 2),
    ("sweep", ["--reuse", "{file}"], 2),
    ("sweep", ["--num-lanes", str(10**9)], 2),
    ("sweep", ["--num-updates", str(10**8)], 2),
    ("sweep", ["--val-episodes-per-room", "0"], 2),
    # tune and paper
    ("tune", ["--grid", "learning_rate"], 2),
    ("tune", ["--grid", "learning_rate="], 2),
    ("tune", ["--grid", "nothing=1,2"], 2),
    ("tune", ["--grid", "learning_rate=1e-3,1e-3"], 2),
    ("tune", ["--seeds", "0", "--grid", "learning_rate=1e-3,3e-4"], 2),
    ("tune", ["--seeds", str(10**6), "--grid", "learning_rate=1e-3,3e-4"], 2),
    ("tune", ["--methods", "a3c", "a3c", "--grid", "learning_rate=1e-3,3e-4"], 2),
    ("paper", ["--exclude", "bogus"], 2),
    ("paper", ["--arms", "bogus@learning_rate=1"], 2),
    ("paper", ["--seeds", "0"], 2),
    ("paper", ["--seeds", str(10**6)], 2),
    ("paper", ["--seed", TOO_BIG], 2),
    # the readers: a run that is not there, a file, a run with nothing trained
    ("evaluate", ["--run", "{missing}"], 2),
    ("evaluate", ["--run", "{file}"], 2),
    ("evaluate", ["--run", "{run}", "--split", "train"], 2),
    ("evaluate", ["--run", "{run}"], 2),  # run.json, no checkpoint
    ("evaluate", ["--run", "{uni}"], 2),
    ("compare", ["--run", "{missing}"], 2),
    ("compare", ["--run", "{run}"], 2),
    ("compare", ["--run", "{sweep}", "--pairs", "a3c:bogus"], 2),
    ("probe", ["--run", "{missing}"], 2),
    ("probe", ["--run", "{run}"], 2),
    ("failures", ["--run", "{missing}"], 2),
    ("failures", ["--run", "{run}", "--split", "nowhere"], 2),
    ("cvae_compare", ["--run", "{missing}"], 2),
    ("cvae_compare", ["--run", "{run}"], 2),
    ("foresight", ["--resets", "0"], 2),
    ("foresight", ["--setup", "xyz"], 2),
    ("foresight", ["--layout", "castle"], 2),
    ("foresight", ["--perception-range", "-1"], 2),
    # outputs that cannot be written, and --resume of what is not a run
    ("train", ["--out", "{file}"], 2),
    ("train", ["--out", "{ro}"], 2),
    ("train", ["--out", "{under_file}"], 2),
    ("train", ["--out", "{missing}", "--resume"], 2),
    ("train", ["--out", "{uni}", "--resume"], 2),
    ("train", ["--out", "{sweep}", "--resume"], 2),
    ("train", ["--out", "{run}", "--resume", "--seed", "5"], 2),
    ("train", ["--out", "{run}"], 2),  # already exists
    ("sweep", ["--out", "{file}"], 2),
    ("sweep", ["--out", "{ro}"], 2),
    ("sweep", ["--out", "{under_file}"], 2),
    ("sweep", ["--out", "{run}"], 2),
    ("sweep", ["--out", "{missing}", "--resume"], 2),
    ("sweep", ["--out", "{sweep}", "--resume", "--seeds", "3"], 2),
    ("tune", ["--out", "{file}", "--grid", "learning_rate=1e-3,3e-4"], 2),
    ("paper", ["--out", "{file}"], 2),
    ("foresight", ["--out", "{file}"], 2),
    ("foresight", ["--seed", TOO_BIG], 2),
    ("foresight", ["--out", "{run}"], 2),  # holds foresight.md
]

# The files a damaged folder can hold, and the program (argv) that reads each.
DAMAGE = {"empty": b"", "truncated": b'{"format": 3, "arm": "a3', "binary": bytes(range(256)), "a list": b"[1, 2]"}
READERS = {
    "run.json": [
        ["train", "--resume", "--out", "{run}"],
        ["evaluate", "--run", "{run}"],
        ["probe", "--run", "{run}"],
        ["cvae_compare", "--run", "{run}"],
    ],
    "progress.json": [["train", "--resume", "--out", "{run}"]],
    "results.json": [["train", "--resume", "--out", "{run}"]],
    "sweep.json": [["sweep", "--resume", "--out", "{sweep}"], ["compare", "--run", "{sweep}"]],
}
DAMAGED = [(name, damage, argv) for name, argvs in READERS.items() for argv in argvs for damage in DAMAGE]


# ---------------------------------------------------------------------- the folders
def started_run(folder: Path, exist_ok: bool = False) -> Path:
    """A run folder as train leaves it before its first chunk: run.json (and what is there)."""
    config, schedule = presets.preset("tiny", "a3c+foresit")
    folder.mkdir(parents=True, exist_ok=exist_ok)
    rundir.write_run_info(folder, Run(folder, config, schedule, (0,), "a3c+foresit", "tiny").info())
    return folder


def started_sweep(folder: Path) -> Path:
    """A sweep folder as sweep leaves it before its first chunk: sweep.json only."""
    folder.mkdir(parents=True)
    rundir.write_started_args(
        folder / "sweep.json", sweeps.Sweep(methods=("a3c", "a3c+foresit"), preset="tiny", seeds=2, out=folder), ()
    )
    return folder


def places(root: Path) -> dict[str, Path]:
    """The placeholders of the table, made under `root`."""
    ro = root / "read-only"
    ro.mkdir()
    (root / "plain file").write_text("not a folder\n")
    (root / "run" / "foresight.md").parent.mkdir()
    (root / "run" / "foresight.md").write_text("a report the user keeps\n")
    places = {
        "out": root / "out",
        "file": root / "plain file",
        "ro": ro / "out",
        "uni": root / "ein Lauf é ü 跑",
        "under_file": root / "plain file" / "out",
        "run": started_run(root / "run", exist_ok=True),
        "sweep": started_sweep(root / "sweep"),
        "missing": root / "no such",
    }
    ro.chmod(0o555)
    return places


def listing(root: Path) -> dict[str, str]:
    """Every path under `root` with a digest of its bytes (folders: 'dir'; symbolic links:
    where they point, never followed), and its mode."""
    out = {}
    for path in sorted(root.rglob("*")):
        if path.is_symlink():
            out[str(path.relative_to(root))] = f"link to {os.readlink(path)}"
            continue
        kind = "dir" if path.is_dir() else hashlib.sha256(path.read_bytes()).hexdigest()
        out[str(path.relative_to(root))] = f"{kind} {oct(path.stat().st_mode & 0o777)}"
    return out


def call(program: str, argv: list[str], capsys) -> tuple[int, str]:
    """`python -m experiments.<program> argv`, in-process: (exit status, stderr)."""
    cli = importlib.import_module(f"experiments.{program}").cli
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        cli(argv)
    return exc.value.code, capsys.readouterr().err


def check_refused(program: str, argv: list[str], status: int, root: Path, capsys) -> str:
    """Run the case; assert its status, one `error:` line or tyro's framed message, no
    traceback, and the tree under `root` as it was. Returns stderr."""
    before = listing(root)
    code, err = call(program, argv, capsys)
    shown = f"{program} {' '.join(argv)} -> {code}:\n{err}"
    assert code == status, shown
    assert "Traceback" not in err, shown
    lines = err.strip().splitlines()
    framed = "For full helptext" in err  # tyro's message, boxed on a terminal, ruled with dashes here
    assert framed or (len([x for x in lines if x.startswith("error:")]) == 1 and lines[-1].startswith("error:")), shown
    assert listing(root) == before, f"{shown}\nthe folder changed"
    return err


def fill(argv: list[str], where: dict[str, Path], out_given: bool) -> list[str]:
    argv = [a.format(**{k: str(v) for k, v in where.items()}) for a in argv]
    return argv if out_given else [*argv, "--out", str(where["out"])]


WRITERS = ("train", "sweep", "tune", "paper", "foresight")


@pytest.fixture
def root(tmp_path, cheap_experiments):
    yield tmp_path
    if (tmp_path / "read-only").is_dir():
        (tmp_path / "read-only").chmod(0o755)  # so that pytest can delete it


# ---------------------------------------------------------------------- the table
@pytest.mark.parametrize("program,argv,status", FLAGS, ids=[f"{p} {' '.join(a)}"[:60] for p, a, _ in FLAGS])
def test_a_bad_flag_is_refused_in_one_line_and_writes_nothing(program, argv, status, root, capsys):
    if "{ro}" in argv and getattr(os, "geteuid", lambda: 1)() == 0:
        pytest.skip("root writes into a read-only folder")
    where = places(root)
    given_out = "--out" in argv or program not in WRITERS
    extra = ["--preset", "tiny"] if program in ("train", "sweep", "tune", "paper") and "--preset" not in argv else []
    check_refused(program, fill([*argv, *extra], where, given_out), status, root, capsys)


@pytest.mark.parametrize("name,damage,argv", DAMAGED, ids=[f"{n} {d} {a[0]}" for n, d, a in DAMAGED])
def test_a_damaged_run_folder_is_named_in_one_line_and_left_as_it_is(name, damage, argv, root, capsys):
    where = places(root)
    folder = where["sweep" if name == "sweep.json" else "run"]
    (folder / name).write_bytes(DAMAGE[damage])
    err = check_refused(argv[0], fill(argv[1:], where, True), 2, root, capsys)
    assert name in err or "run.json" in err or f"{folder} is not a sweep folder" in err, err  # what stops it


def test_the_fuzz_table_covers_every_program():
    assert {p for p, _, _ in FLAGS} == set(PROGRAMS)
    assert len(FLAGS) + len(DAMAGED) >= 77


# ---------------------------------------------------------------------- a strategy
FIELDS = ("--num-lanes", "--num-steps", "--hidden-size", "--chunk-updates", "--test-episodes-per-room", "--seed")


def bad_int(flag):
    """A value out of flag's range: counts start at 1, a seed at 0; either may overflow int64."""
    low = -1 if flag == "--seed" else 0
    return st.one_of(st.integers(max_value=low), st.integers(min_value=2**63, max_value=2**80))


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    case=st.sampled_from(FIELDS).flatmap(lambda f: st.tuples(st.just(f), bad_int(f))),
    program=st.sampled_from(("train", "sweep")),
)
@example(case=("--seed", -1), program="train")
@example(case=("--seed", -1), program="sweep")
@example(case=("--num-lanes", 0), program="train")
def test_any_out_of_range_count_is_refused(case, program, root, capsys, tmp_path_factory):
    flag, value = case
    if program == "sweep" and flag in ("--chunk-updates",):
        flag = "--seeds"
    sub = tmp_path_factory.mktemp("case")
    argv = ["--preset", "tiny", flag, str(value), "--out", str(sub / "out")]
    check_refused(program, argv, 2, sub, capsys)


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    name=st.sampled_from(["run.json", "progress.json", "results.json"]),
    data=st.one_of(
        st.binary(max_size=64), st.sampled_from(list(DAMAGE.values())), st.text(max_size=32).map(str.encode)
    ),
    cut=st.integers(min_value=0, max_value=40),
)
def test_any_damage_to_a_run_file_is_named(name, data, cut, root, capsys, tmp_path_factory):
    sub = tmp_path_factory.mktemp("case")
    folder = started_run(sub / "run")
    whole = (folder / "run.json").read_bytes()
    damaged = whole[:cut] if name == "run.json" and not data else data
    if damaged == whole or (name != "run.json" and not damaged.strip()):
        damaged = b"\x00"  # a file that parses is not damage; an empty one of these is read as damage too
    (folder / name).write_bytes(damaged)
    check_refused("train", ["--resume", "--out", str(folder)], 2, sub, capsys)


# ====================================================================== issue 80's classes
# Each class is a hypothesis strategy of cases and a body that asserts what a user must see
# for one case. `fuzz` runs a body over a strategy's cases, derandomized (the same cases on
# every run and machine), and returns the failures: a class's test asserts there are none,
# and its mutation check, with the fix undone, that there are.
FUZZ = settings(
    derandomize=True,
    database=None,
    deadline=None,
    phases=[Phase.generate],
    suppress_health_check=list(HealthCheck),
)


def fuzz(strategy, body, examples: int) -> list[str]:
    """What goes wrong when `body` runs on `examples` cases drawn from `strategy`: one line
    per failed case (an assertion, or an exception the body did not expect)."""
    failures = []

    @settings(FUZZ, max_examples=examples)
    @given(strategy)
    def run(case):
        try:
            body(case)
        except (Exception, pytest.fail.Exception) as e:
            failures.append(f"{case!r}: {type(e).__name__}: {e}"[:600])

    run()
    return failures


def drawn(strategy, examples: int) -> list:
    """The cases `fuzz(strategy, body, examples)` gives its body."""
    cases = []
    fuzz(strategy, cases.append, examples)
    return cases


def passes(strategy, body, examples: int) -> None:
    failures = fuzz(strategy, body, examples)
    assert not failures, f"{len(failures)} of {examples} cases failed:\n" + "\n".join(failures)


def one_line(error: BaseException) -> str:
    text = str(error)
    assert "\n" not in text.strip(), text
    return text


class StartedWriting(Exception):
    """Raised where a program would claim its --out (`rundir.claim`): in a mutation check,
    a program that let a bad case through is stopped there, before it trains."""


def stop_at_claim(monkeypatch) -> None:
    def claim(path):
        raise StartedWriting(f"{path} claimed: the program got past its checks")

    monkeypatch.setattr(rundir, "claim", claim)


# ---------------------------------------------------------------------- arms and flags (item 1)

# The values of each str field an arm can set (Config's own lists).
CHOICES = {
    "rollout": ROLLOUTS,
    "gradient": GRADIENTS,
    "value_head": config_module.VALUE_HEADS,
    "attention_value_init": config_module.ATTENTION_VALUE_INITS,
    "attention_key_gradient": config_module.ATTENTION_KEY_GRADIENTS,
    "imagination_optimizer": config_module.IMAGINATION_OPTIMIZERS,
    "imagination_noise": config_module.IMAGINATION_NOISES,
    "imagination_input": config_module.IMAGINATION_INPUTS,
    "evaluation_noise": config_module.EVALUATION_NOISES,
    "aux_target": config_module.AUX_TARGETS,
}
# The ints the tiny preset takes where not any count does: the environment's 6 actions, f_w's
# last width (32), a divisor of its buffer of 2; maml_inner_updates may be 0.
INTS = {"num_actions": (6,), "hidden_size": (32,), "imagination_batch": (1, 2)}
# Bools that need another field beside them (aux_permute, a target's content control, needs a
# target): set alone, only their default is valid.
NEEDS_ANOTHER = ("aux_permute",)


def _arm_can_set(field: str) -> bool:
    """Whether `split_arm` takes `field` in an arm (its rules: a scalar field, not a scene's)."""
    default = getattr(Config(), field)
    text = str(default).lower() if isinstance(default, bool) else str(default)
    try:
        presets.split_arm(f"a3c@{field}={text}")
    except ValueError:
        return False
    return True


ARM_FIELDS = tuple(f for f in field_types() if _arm_can_set(f))
ARM_METHODS = ("a3c", "a3c+foresit", "a3c+critic", "A3C+Foresit", "a3c+rnd")


@st.composite
def spelt_values(draw, field: str):
    """(value, its spelling in an arm) for `field`: a value the tiny preset takes, spelt in
    one of the ways `split_arm` reads as it (1e-3 or 0.001, +5 or 05, TRUE or true)."""
    kind = type(getattr(Config(), field))
    if kind is bool:
        value = draw(st.booleans()) if field not in NEEDS_ANOTHER else getattr(Config(), field)
        return value, draw(st.sampled_from((str(value).lower(), str(value), str(value).upper())))
    if kind is str:
        value = draw(st.sampled_from(CHOICES[field]))
        return value, value
    if kind is int:
        low = 0 if field == "maml_inner_updates" else 1
        value = draw(st.sampled_from(INTS[field]) if field in INTS else st.integers(low, 64))
        return value, draw(st.sampled_from((str(value), f"+{value}", f"0{value}", f" {value} ")))
    m, e = draw(st.integers(1, 99)), draw(st.integers(-4, -2))  # a decimal in (0, 1): every float field takes one
    value = float(f"{m}e{e}")
    return value, draw(st.sampled_from((repr(value), f"{m}e{e}", f"{m}E{e}", repr(value) + "000")))


class ArmCase(NamedTuple):
    preset: str
    arm: str  # as the user writes it
    field: str  # the field the arm sets and a flag gives too
    arm_value: object
    flag_value: object  # equal to arm_value: a flag that agrees


@st.composite
def arm_cases(draw, agree: bool = False, cli: bool = False):
    """An arm setting 1-3 fields (in any order, any spelling, maybe a trailing comma) and a
    flag giving one of them again: another value (refused), or with `agree` the same one
    (kept; then the arm sets that field alone). `cli`: fields a program has a flag for."""
    fields = [f for f in ARM_FIELDS if not (cli and f == "num_actions")]
    if cli or not agree:  # a conflict needs a second value
        fields = [f for f in fields if f not in INTS or len(INTS[f]) > 1]
    chosen = draw(st.lists(st.sampled_from(fields), min_size=1, max_size=1 if agree else 3, unique=True))
    field = chosen[0]
    spelt = {f: draw(spelt_values(f)) for f in chosen}
    value = spelt[field][0]
    other = value if agree else draw(spelt_values(field).map(lambda v: v[0]).filter(lambda v: v != value))
    order = draw(st.permutations(chosen))
    method = draw(st.sampled_from(ARM_METHODS))
    tail = draw(st.sampled_from(("", ",", " ")))
    arm = f"{method}@" + ",".join(f"{f}={spelt[f][1]}" for f in order) + tail
    name = "tiny" if agree or cli else draw(st.sampled_from(tuple(presets.PRESETS)))
    return ArmCase(name, arm, field, value, other)


def flag(field: str) -> str:
    return "--" + field.replace("_", "-")


def check_arm_and_flag(case: ArmCase) -> None:
    """A flag that agrees with the arm is kept; one that gives another value is refused in
    one line naming the arm as written, the field, and the flag with its value."""
    given = {case.field: case.flag_value}
    if case.flag_value == case.arm_value:
        config, _ = presets.preset(case.preset, case.arm, **given)
        assert getattr(config, case.field) == case.arm_value, config
        return
    try:
        config, _ = presets.preset(case.preset, case.arm, **given)
    except ValueError as e:
        line = one_line(e)
    else:
        raise AssertionError(f"kept: {case.field}={getattr(config, case.field)!r} under the label {case.arm!r}")
    assert f"arm {case.arm!r} sets {case.field}=" in line, line
    assert f"{flag(case.field)} gives {case.flag_value!r}" in line, line


class MamlCase(NamedTuple):
    preset: str
    method: str
    field: str
    value: object
    via: str  # "arm" (METHOD@field=value) or "flag"
    broken: bool  # whether the value breaks the method's requirement


@st.composite
def maml_cases(draw, broken: bool | None = None):
    """A maml method (any spelling) given num_steps, a rollout or a gradient by its arm or a
    flag: one below its needs (fewer steps than the time limit, packed windows, the replay
    gradient) or one that meets them."""
    name = draw(st.sampled_from(("tiny", "quick", "house")))
    limit = training_limit(name)
    method = draw(st.sampled_from(("a3c+maml", "maml", "A3C+MAML", "a3c+maml+foresit", "maml+foresit")))
    field = draw(st.sampled_from(("num_steps", "num_steps", "rollout", "gradient")))
    broken = draw(st.booleans()) if broken is None else broken
    if field == "num_steps":
        value = draw(st.integers(1, limit - 1) if broken else st.integers(limit, limit + 40))
    else:
        value = {"rollout": ("episodes", "packed"), "gradient": ("through_rollout", "replay")}[field][broken]
    return MamlCase(name, method, field, value, draw(st.sampled_from(("arm", "flag"))), broken)


def training_limit(name: str) -> int:
    """The training time limit of preset `name`'s scenes (rooms 30 steps, houses 60)."""
    from envs.gridnav import time_limits

    return int(max(time_limits(True, presets.PRESETS[name][0].get("layout", "room"))))


def maml_arm(case: MamlCase) -> tuple[str, dict]:
    if case.via == "arm":
        return f"{case.method}@{case.field}={case.value}", {}
    return case.method, {case.field: case.value}


def check_maml_requirement(case: MamlCase) -> None:
    """What meets maml's needs is kept as given; what breaks them is refused in one line
    naming what the user gave and what the method needs (for num_steps, the minimum, and no
    hint to use packed windows, which maml cannot)."""
    arm, flags = maml_arm(case)
    limit = training_limit(case.preset)
    if not case.broken:
        config, _ = presets.preset(case.preset, arm, **flags)
        assert getattr(config, case.field) == case.value, config
        assert (config.rollout, config.gradient) == ("episodes", "through_rollout"), config
        assert config.num_steps >= limit, config
        return
    try:
        config, _ = presets.preset(case.preset, arm, **flags)
    except ValueError as e:
        line = one_line(e)
    else:
        raise AssertionError(f"kept: {case.field}={getattr(config, case.field)!r} for {arm!r} {flags}")
    said = f"arm {arm!r} sets {case.field}=" if case.via == "arm" else f"{flag(case.field)} {case.value!r}"
    assert said in line and parse_method(case.method).name in line, line
    if case.field == "num_steps":
        assert f"num_steps >= {limit}" in line and "rollout='packed'" not in line, line


def preset_before_item_1(name: str, method: str, **overrides):
    """`presets.preset` as it was before issue 80's item 1 (fa23e36^): the arm's fields over
    the preset's, then the method's required fields and the flags over both, unchecked."""
    method, arm_fields = presets.split_arm(method)
    presets.check_method(method)
    fields, schedule = presets.PRESETS[name]
    fields = {**fields, **arm_fields}
    given = {k: v for k, v in overrides.items() if v is not None}
    required = parse_method(method).required_config
    if required.get("rollout") == "episodes":
        from envs.gridnav import time_limits

        limit = int(max(time_limits(True, given.get("layout", fields.get("layout", Config.layout)))))
        required = {**required, "num_steps": max(fields.get("num_steps", Config.num_steps), limit)}
    return Config(method=method, **{**fields, **required, **given}), schedule


def test_the_arm_fuzz_knows_every_field_an_arm_can_set():
    assert {"learning_rate", "num_steps", "rollout", "maml_first_order", "imagination_input"} <= set(ARM_FIELDS)
    assert not {"method", "setup", "layout", "priors", "perception_range", "room_types"} & set(ARM_FIELDS)
    assert {f for f in ARM_FIELDS if type(getattr(Config(), f)) is str} == set(CHOICES)


def test_an_arm_and_a_flag_that_disagree_are_refused_and_agreeing_ones_kept():
    passes(arm_cases(), check_arm_and_flag, 40)
    passes(arm_cases(agree=True), check_arm_and_flag, 25)


def test_an_arm_or_flag_below_a_methods_needs_is_refused_and_one_that_meets_them_kept():
    passes(maml_cases(), check_maml_requirement, 30)


def cli_arm_case(program: str, case, root: Path) -> tuple[list[str], list[str]]:
    """(argv, words its one line must hold) of an ArmCase or a broken MamlCase given to
    train (--method ARM) or sweep (--methods a3c ARM)."""
    if isinstance(case, ArmCase):
        arm, value = case.arm, case.flag_value
        flags = [flag(case.field), str(value)]
        words = [repr(case.arm), f"{flag(case.field)} gives {value!r}"]
    else:
        arm, given = maml_arm(case)
        flags = [x for k, v in given.items() for x in (flag(k), str(v))]
        words = [parse_method(case.method).name, repr(arm) if case.via == "arm" else flag(case.field)]
    where = ["--methods", "a3c", arm, "--seeds", "1"] if program == "sweep" else ["--method", arm]
    return ["--preset", case.preset, *where, *flags, "--out", str(root / "out")], words


def check_cli_arm(program_case, factory, capsys) -> None:
    """A program refuses the case in one line naming both sides, and writes nothing."""
    program, case = program_case
    root = factory.mktemp("case")
    argv, words = cli_arm_case(program, case, root)
    err = check_refused(program, argv, 2, root, capsys)
    assert all(w in err for w in words), (words, err)


PROGRAMS_WITH_ARMS = st.sampled_from(("train", "sweep"))
CLI_CONFLICTS = st.tuples(PROGRAMS_WITH_ARMS, arm_cases(cli=True))
CLI_MAML = st.tuples(PROGRAMS_WITH_ARMS, maml_cases(broken=True))


def test_train_and_sweep_refuse_an_arm_and_flag_conflict_before_writing(root, capsys, tmp_path_factory):
    passes(CLI_CONFLICTS, lambda case: check_cli_arm(case, tmp_path_factory, capsys), 6)
    passes(CLI_MAML, lambda case: check_cli_arm(case, tmp_path_factory, capsys), 4)


def test_mutation_arms_and_flags_fuzz_fails_with_item_1_undone(root, capsys, tmp_path_factory, monkeypatch):
    """presets.preset as before item 1 (the flag and the method's needs silently over the
    arm): the same generated cases fail, in the library and through the programs (each
    stopped where it would claim its --out, before it trains)."""
    from experiments import train

    monkeypatch.setattr(presets, "preset", preset_before_item_1)
    monkeypatch.setattr(train, "preset", preset_before_item_1)
    monkeypatch.setattr(sweeps, "preset", preset_before_item_1)
    stop_at_claim(monkeypatch)
    assert len(fuzz(arm_cases(), check_arm_and_flag, 40)) == 40  # every conflict
    broken = sum(case.broken for case in drawn(maml_cases(), 30))
    assert len(fuzz(maml_cases(), check_maml_requirement, 30)) == broken > 0  # every broken one
    cli = lambda case: check_cli_arm(case, tmp_path_factory, capsys)  # noqa: E731
    assert len(fuzz(CLI_CONFLICTS, cli, 6)) == 6
    assert len(fuzz(CLI_MAML, cli, 4)) == 4


# ---------------------------------------------------------------------- paths the OS refuses (item 2)
# (program, its path flag): every writer's --out, train's --resume, every reader's --run.
PATH_FLAGS = (
    ("train", "--out"),
    ("train", "--resume --out"),
    ("sweep", "--out"),
    ("tune", "--out"),
    ("paper", "--out"),
    ("foresight", "--out"),
    ("evaluate", "--run"),
    ("probe", "--run"),
    ("failures", "--run"),
    ("cvae_compare", "--run"),
    ("compare", "--run"),
)
PROGRAM_ARGS = {
    "train": ["--preset", "tiny"],
    "sweep": ["--preset", "tiny", "--methods", "a3c", "--seeds", "1"],
    "tune": ["--preset", "tiny", "--grid", "learning_rate=1e-3,3e-4"],
    "paper": ["--preset", "tiny"],
}
SHORT_NAMES = st.text(alphabet="abxyz019_-é跑 ", min_size=1, max_size=6).filter(lambda n: n.strip() == n)
# Characters of 1 to 4 bytes in UTF-8: a name's bytes, not its characters, meet NAME_MAX.
LONG_NAME_CHARS = "ab_-. 0éü跑😀"


class PathCase(NamedTuple):
    program: str
    flag: str
    kind: str  # "long" (a name past 255 bytes), "loop" (symbolic links in a cycle), "dangling", "arm"
    above: tuple  # folders made above the bad name
    bad: str  # the bad name (a long name, a link of the loop, the dangling link, or the arm)
    links: tuple  # (name, target) of each link made beside it
    below: tuple  # names after it on the path


@st.composite
def path_cases(draw, flags=PATH_FLAGS, kinds=("long", "loop", "dangling")):
    """A path, given as a program's --out or --run, whose bad name is at a random depth:
    below 0-2 folders that exist and above 0-2 names that do not. The bad name is longer
    than 255 bytes (any characters, 1-4 bytes each), a link in a cycle of 1-3 links, or a
    link to nothing; or ("arm", for sweep) an arm that parses but is too long for a folder name."""
    program, flag = draw(st.sampled_from(flags))
    kind = draw(st.sampled_from(kinds))
    above = tuple(draw(st.lists(SHORT_NAMES, max_size=2)))
    below = tuple(draw(st.lists(SHORT_NAMES, max_size=2)))
    links = ()
    if kind == "long":
        unit = draw(st.text(alphabet=LONG_NAME_CHARS, min_size=1, max_size=6).filter(lambda u: u.strip() == u))
        size = draw(st.integers(256, 700))
        bad = unit * -(-size // len(unit.encode()))
    elif kind == "loop":
        cycle = draw(st.lists(SHORT_NAMES, min_size=1, max_size=3, unique=True))
        links = tuple((a, b) for a, b in zip(cycle, cycle[1:] + cycle[:1]))
        bad = draw(st.sampled_from(cycle))
    elif kind == "dangling":
        bad = draw(SHORT_NAMES)
        links = ((bad, "⊘" + draw(st.sampled_from(("", "/deeper", "/a/b")))),)  # "⊘" names nothing here
    else:  # a sweep arm: fields at values the preset takes, spelt with zeros to past 255 bytes
        fields = draw(st.lists(st.sampled_from(("learning_rate", "gamma", "entropy_coef")), min_size=1, unique=True))
        pad = draw(st.integers(256, 400)) // len(fields)
        bad = "a3c@" + ",".join(f"{f}=0.{'0' * pad}1" if f != "gamma" else f"{f}=0.9{'0' * pad}" for f in fields)
    return PathCase(program, flag, kind, above, bad, links, below)


LONG_ARMS = path_cases((("sweep", "--out"),), ("arm",))
PATH_WORDS = {
    "long": ("longer than the 255", "File name too long"),
    "loop": ("leads back to itself",),
    "dangling": ("which is not there",),
    "arm": ("longer than the 255 a folder name can have",),
}


def check_path_case(case: PathCase, factory, capsys) -> None:
    """The program refuses in one line saying what is wrong with the path (its bytes, the
    loop, the missing target), without a traceback, and leaves the folder as it was."""
    root = factory.mktemp("case")
    parent = root.joinpath(*case.above)
    parent.mkdir(parents=True, exist_ok=True)
    for name, target in case.links:
        (parent / name).symlink_to(target)
    if case.kind == "arm":
        path = parent.joinpath(*case.below, "sweep")
        argv = ["--preset", "tiny", "--methods", case.bad, "a3c", "--seeds", "1", "--out", str(path)]
    else:
        path = parent.joinpath(case.bad, *case.below)
        argv = [*PROGRAM_ARGS.get(case.program, []), *case.flag.split(), str(path)]
    err = check_refused(case.program, argv, 2, root, capsys)
    assert any(w in err for w in PATH_WORDS[case.kind]), err


def test_a_path_the_os_refuses_is_one_line_and_makes_nothing(root, capsys, tmp_path_factory):
    check = lambda case: check_path_case(case, tmp_path_factory, capsys)  # noqa: E731
    passes(path_cases(), check, 14)
    for program_flag in PATH_FLAGS:  # every program and kind, whatever the draws above gave
        for kind in ("long", "loop", "dangling"):
            passes(path_cases((program_flag,), (kind,)), check, 1)
    passes(LONG_ARMS, check, 3)


def test_the_path_fuzz_covers_every_program():
    assert {program for program, _ in PATH_FLAGS} == set(PROGRAMS)


def test_mutation_path_fuzz_fails_with_item_2_undone(root, capsys, tmp_path_factory, monkeypatch):
    """`rundir.check_path` a no-op, no name too long (NAME_MAX, which sweep's arm check reads,
    past any name), and ENAMETOOLONG and ELOOP no longer among the errors `errors.run_cli`
    says in one line: the same generated paths fail (foresight left out: it would measure
    for minutes before it writes)."""
    from experiments import errors

    monkeypatch.setattr(rundir, "check_path", lambda path, what="--out": None)
    monkeypatch.setattr(rundir, "NAME_MAX", 10**9)
    monkeypatch.setattr(errors, "_USER_ERRNOS", errors._USER_ERRNOS - {errno.ENAMETOOLONG, errno.ELOOP})
    flags = tuple(f for f in PATH_FLAGS if f[0] != "foresight")
    check = lambda case: check_path_case(case, tmp_path_factory, capsys)  # noqa: E731
    found = fuzz(path_cases(flags), check, 14)
    assert len(found) == 14, found
    assert len(fuzz(LONG_ARMS, check, 3)) == 3


# ---------------------------------------------------------------------- Config's types (item 3)
FIELD_TYPES = field_types()
# What a field's valid values are, beyond its type: the action count is the environment's,
# f_w's last width is hidden_size (512 by default), imagination_batch divides buffer_size (32).
VALID_INTS = {"num_actions": (6,), "hidden_size": (512,), "imagination_batch": (1, 2, 4, 8, 16, 32)}
ROOMS = ("kitchen", "living_room", "bedroom", "bathroom")


def _kind(field: str):
    """A field's type: bool, int, float, str, 'optional float', 'ints' or 'strs' (tuples)."""
    hint = FIELD_TYPES[field]
    if typing.get_origin(hint) is typing.Union:
        return "optional float"
    if typing.get_origin(hint) is tuple:
        return {int: "ints", str: "strs"}[typing.get_args(hint)[0]]
    return hint


@st.composite
def wrong_typed(draw):
    """(field, value) for a random Config field and a value of another type: a string for a
    bool or a number (numeric strings included), a bool or a float for an int, a bool for a
    float, a number for a str, a string or a tuple holding another type for a tuple, None."""
    field = draw(st.sampled_from(tuple(FIELD_TYPES)))
    kind = _kind(field)
    numeric_text = st.one_of(st.integers(-5, 600).map(str), st.floats(0.001, 2).map(repr), st.just("1e-3"))
    text = st.one_of(numeric_text, st.sampled_from(("True", "False", "true", "0", "yes", "")), st.text(max_size=6))
    if kind is bool:
        wrong = st.one_of(text, st.integers(0, 1), st.floats(0, 1), st.none(), st.integers(0, 1).map(np.int64))
    elif kind is int:
        whole = st.integers(1, 64)
        wrong = st.one_of(
            text, st.booleans(), whole.map(float), whole.map(np.float32), st.floats(1.1, 60), st.none(), whole.map(str)
        )
    elif kind is float or kind == "optional float":
        wrong = st.one_of(numeric_text, text, st.booleans(), st.booleans().map(np.bool_), st.just([0.5]))
        wrong = wrong if kind == "optional float" else st.one_of(wrong, st.none())
    elif kind is str:
        choices = CHOICES.get(field) or {"method": ("a3c",), "setup": ("savn",), "layout": ("room",)}[field]
        wrong = st.one_of(
            st.integers(),
            st.floats(allow_nan=False),
            st.booleans(),
            st.none(),
            st.sampled_from(choices).map(str.encode),
        )
        wrong = st.one_of(wrong, st.sampled_from(choices).map(lambda c: (c,)))
    elif kind == "ints":
        widths = st.lists(st.integers(1, 64), min_size=1, max_size=3).map(lambda w: [*w, 512])
        wrong = st.one_of(
            widths.map(lambda w: ",".join(map(str, w))),  # a string of widths
            st.integers(1, 512),
            st.tuples(widths, st.integers(0, 3), st.sampled_from((float, str, bool, np.float32))).map(
                lambda t: tuple(t[2](x) if i == t[1] % len(t[0]) else x for i, x in enumerate(t[0]))
            ),
            st.none(),
        )
    else:  # strs: room types (a str alone is one room type: taken)
        wrong = st.one_of(
            st.integers(0, 3),
            st.tuples(st.sampled_from(ROOMS), st.one_of(st.integers(0, 3), st.none(), st.just(b"kitchen"))),
            st.none(),
        )
    return field, draw(wrong)


def check_wrong_type_refused(case) -> None:
    """Config refuses the value in one line that names the field and says its type."""
    field, value = case
    try:
        config = Config(**{field: value})
    except ValueError as e:
        line = one_line(e)
    else:
        raise AssertionError(f"Config took {field}={value!r} ({type(value).__name__}) as {getattr(config, field)!r}")
    assert line.startswith(f"{field} must be "), line


def _plain(x) -> bool:
    """Whether `x` is a plain Python value (no numpy scalar, array or list inside)."""
    if isinstance(x, tuple):
        return all(map(_plain, x))
    return type(x) in (bool, int, float, str, type(None))


@st.composite
def acceptably_typed(draw):
    """(field, value, what Config must hold) for a random field: a valid value given as
    another acceptable type: an int for a float, a list or a numpy array for a tuple, a
    numpy scalar (or a 0-d array) for a number, a bool or a str, a room type's name alone."""
    field = draw(st.sampled_from(tuple(FIELD_TYPES)))
    kind = _kind(field)
    if kind is bool:
        value = draw(st.booleans()) if field not in NEEDS_ANOTHER else getattr(Config(), field)
        return field, draw(st.sampled_from((np.bool_(value), np.array(value), value))), value
    if kind is int:
        low = 0 if field == "maml_inner_updates" else 1
        value = draw(st.sampled_from(VALID_INTS[field]) if field in VALID_INTS else st.integers(low, 64))
        given = draw(st.sampled_from((np.int64, np.int32, np.uint16, np.array, int)))(value)
        return field, given, value
    if kind is float or kind == "optional float":
        value = draw(st.one_of(st.just(1), st.integers(1, 99).map(lambda m: m / 100)))
        given = draw(st.sampled_from((np.float32, np.float64, np.array, float, np.int64, int)))
        if given in (np.int64, int):
            value = 1 if kind is float else draw(st.integers(1, 40))  # an int: 1 is valid for every float field
        given = given(value)
        return field, given, float(np.float32(value)) if isinstance(given, np.float32) else value
    if kind is str:
        choices = CHOICES.get(field) or {"method": ("a3c", "a3c+foresit", "a3c+critic"), "setup": ("savn",)}.get(
            field, ("room", "house")
        )
        value = draw(st.sampled_from(choices))
        return field, draw(st.sampled_from((np.str_, str)))(value), value
    if kind == "ints":
        widths = draw(st.lists(st.integers(1, 64), max_size=4)) + [512]
        how = draw(st.sampled_from(("list", "array", "numpy items")))
        given = {"list": list, "array": np.array, "numpy items": lambda w: [np.int64(x) for x in w]}[how](widths)
        return field, given, tuple(widths)
    rooms = draw(st.lists(st.sampled_from(ROOMS), min_size=1, max_size=4, unique=True))
    how = draw(st.sampled_from(("list", "name", "numpy strs")))
    if how == "name":
        return field, rooms[0], (rooms[0],)
    return field, list(rooms) if how == "list" else [np.str_(r) for r in rooms], tuple(rooms)


def check_acceptable_type_taken(case) -> None:
    """Config takes the value, holds it as the plain Python value it stands for, and stays
    hashable (a jit static argument) and JSON-able (run.json)."""
    field, value, expected = case
    config = Config(**{field: value})
    held = getattr(config, field)
    assert held == expected and _plain(held), (held, type(held))
    hash(config)
    json.dumps(dataclasses.asdict(config))


def check_wrong_type_in_run_json(case, factory, capsys) -> None:
    """A run.json whose config holds a JSON value of the wrong type for a field: train
    --resume and evaluate refuse it in one line naming the field, and change nothing."""
    (field, value), program = case
    if isinstance(value, (bytes, np.generic)) or (isinstance(value, tuple) and not _plain(value)):
        value = repr(value)  # what JSON holds: a string
    sub = factory.mktemp("case")
    run = started_run(sub / "run")
    info = json.loads((run / "run.json").read_text())
    info["config"][field] = list(value) if isinstance(value, tuple) else value
    (run / "run.json").write_text(json.dumps(info))
    argv = ["--resume", "--out", str(run)] if program == "train" else ["--run", str(run)]
    err = check_refused(program, argv, 2, sub, capsys)
    assert f"{field} must be " in err, err


WRONG_IN_RUN_JSON = st.tuples(wrong_typed(), st.sampled_from(("train", "evaluate")))


def test_a_value_of_the_wrong_type_for_a_config_field_is_refused_naming_it():
    passes(wrong_typed(), check_wrong_type_refused, 60)


def test_a_value_of_an_acceptable_type_is_taken_as_a_plain_value():
    passes(acceptably_typed(), check_acceptable_type_taken, 50)


def test_a_wrong_type_in_a_run_json_is_refused_naming_the_field(root, capsys, tmp_path_factory):
    passes(WRONG_IN_RUN_JSON, lambda case: check_wrong_type_in_run_json(case, tmp_path_factory, capsys), 5)


def test_mutation_config_type_fuzz_fails_with_item_3_undone(monkeypatch):
    """`config.check_type` a no-op: wrong types pass (those another check does not catch);
    `config._plain` the identity: numpy scalars are no longer taken."""
    with monkeypatch.context() as m:
        m.setattr(config_module, "check_type", lambda name, hint, value: None)
        found = fuzz(wrong_typed(), check_wrong_type_refused, 60)
    assert len(found) >= 10, found  # 19 of the 60 when written; the others another check refuses
    with monkeypatch.context() as m:
        m.setattr(config_module, "_plain", lambda value: value)
        found = fuzz(acceptably_typed(), check_acceptable_type_taken, 50)
    assert len(found) >= 10, found  # 29 of the 50 when written; the others plain values already


# ---------------------------------------------------------------------- the library's boundary (item 4)
evaluate_module = importlib.import_module("foresit_jax.evaluate")  # the module (the package exports a function)
API_CONFIG = H.tiny_config("a3c+foresit")  # bathrooms, 16 hidden units: both parameter trees


class PolicyCase(NamedTuple):
    lanes: int  # episodes per room: the lanes the policy acts for
    carry: str  # the initial carry: "array", "pair", "dict" or "none"
    wrong: tuple  # what is wrong, of "signature", "arity", "shape", "dtype", "carry"
    takes: int  # the arguments the policy takes (5 unless its signature is wrong)
    arity: str  # what it returns unless a pair: "bare" (the actions alone), "one" or "three" values
    shape: tuple  # the actions' shape
    dtype: str  # the actions' dtype
    change: str  # what is done to the carry: "dropped", "wrapped", "reshaped", "retyped"


CHECK_ORDER = ("signature", "arity", "shape", "dtype", "carry")
INITIAL_CARRIES = {
    "array": lambda n: jnp.zeros((n, 3)),
    "pair": lambda n: (jnp.zeros((n,)), jnp.zeros((n, 2), jnp.int32)),
    "dict": lambda n: {"h": jnp.zeros((n, 4)), "t": jnp.zeros((), jnp.int32)},
    "none": lambda n: None,
}


@st.composite
def bad_policies(draw):
    """A policy for `evaluate_policy` with one or more things wrong: it takes other than
    five arguments; it returns the actions alone or with no carry or an extra value; actions
    of another shape (a scalar, one per lane and more, too many) or a non-integer dtype; a
    carry dropped, wrapped, with a leaf reshaped or of another dtype. What is right is
    varied too (integer dtypes, carries of several trees)."""
    lanes = draw(st.integers(1, 4))
    wrong = draw(st.sets(st.sampled_from(CHECK_ORDER), min_size=1))
    shape = (lanes,)
    if "shape" in wrong:
        shape = draw(st.sampled_from(((), (lanes, 1), (lanes + 1,), (2, lanes), (1, lanes))))
    dtype = draw(
        st.sampled_from(
            ("float32", "bool", "float16", "complex64") if "dtype" in wrong else ("int32", "int8", "uint8", "int16")
        )
    )
    return PolicyCase(
        lanes,
        draw(st.sampled_from(tuple(INITIAL_CARRIES))),
        tuple(w for w in CHECK_ORDER if w in wrong),
        draw(st.sampled_from((1, 2, 4, 6))) if "signature" in wrong else 5,
        draw(st.sampled_from(("bare", "one", "three"))),
        shape,
        dtype,
        draw(st.sampled_from(("dropped", "wrapped", "reshaped", "retyped"))),
    )


def changed_carry(carry, change: str, lanes: int):
    leaves, tree = jax.tree.flatten(carry)
    if change == "wrapped":
        return (carry,)
    if change == "dropped" or not leaves:  # a carry of no leaves can only be replaced
        return None if leaves else jnp.zeros((lanes,))
    first = leaves[0]
    if change == "reshaped":
        first = jnp.zeros((*first.shape, 2), first.dtype)
    else:
        first = first.astype(jnp.int32 if jnp.issubdtype(first.dtype, jnp.floating) else jnp.float32)
    return jax.tree.unflatten(tree, [first, *leaves[1:]])


def make_policy(case: PolicyCase):
    def returned(carry):
        actions = jnp.zeros(case.shape, case.dtype)
        new = changed_carry(carry, case.change, case.lanes) if "carry" in case.wrong else carry
        if "arity" in case.wrong:
            return {"bare": actions, "one": (actions,), "three": (actions, new, new)}[case.arity]
        return actions, new

    takes = {
        1: lambda obs: returned(None),
        2: lambda obs, key: returned(None),
        4: lambda params, carry, obs, key: returned(carry),
        5: lambda params, carry, obs, first, key: returned(carry),
        6: lambda params, carry, obs, first, key, extra: returned(carry),
    }
    return takes[case.takes]


def policy_words(case: PolicyCase) -> str:
    """What the refusal of the first thing wrong (in the order checked) must say."""
    return {
        "signature": "must take 5 arguments (params, carry, obs, first, key)",
        "arity": f"the policy must return (actions [{case.lanes}] of an integer dtype, carry)",
        "shape": f"must have shape ({case.lanes},), one per lane; got shape {case.shape}",
        "dtype": f"must have an integer dtype (actions 0..5); got {case.dtype}",
        "carry": "carry",
    }[case.wrong[0]]


def check_bad_policy_refused(case: PolicyCase) -> None:
    """evaluate_policy refuses the policy on its first call, in one line starting
    `evaluate_policy:` that names the first thing wrong: not inside JAX's scan or vmap."""
    try:
        evaluate_module.evaluate_policy(
            make_policy(case), None, INITIAL_CARRIES[case.carry], API_CONFIG, "test", episodes_per_room=case.lanes
        )
    except (TypeError, ValueError) as e:
        line = one_line(e)
    else:
        raise AssertionError("evaluate_policy played it")
    assert line.startswith("evaluate_policy: "), line
    assert policy_words(case) in line, line


def test_evaluate_policy_refuses_any_bad_policy_in_one_line():
    passes(bad_policies(), check_bad_policy_refused, 16)


class TraceOnly:
    """The jax module for `foresit_jax.evaluate`, but whose `jit` only traces
    (`jax.eval_shape`): under a mutation, a policy the check lets through is traced, not
    compiled and played for whole episodes."""

    def __getattr__(self, name):
        return getattr(jax, name)

    @staticmethod
    def jit(fn, **kwargs):
        return lambda *args: jax.eval_shape(fn, *args)


def test_mutation_policy_fuzz_fails_with_the_check_undone(monkeypatch):
    """`check_policy_return` and the signature check no-ops: the same bad policies now fail
    inside JAX (or trace through), and the fuzz says so for every one."""
    monkeypatch.setattr(evaluate_module, "check_policy_return", lambda *args, **kwargs: None)
    monkeypatch.setattr(evaluate_module, "_check_policy_signature", lambda policy_fn: None)
    monkeypatch.setattr(evaluate_module, "jax", TraceOnly())
    found = fuzz(bad_policies(), check_bad_policy_refused, 16)
    assert len(found) == 16, found


@functools.cache
def api_state(stacked: bool = False):
    """A training state of API_CONFIG, zeros of its shapes (nothing trains); `stacked`: two seeds."""
    shapes = jax.eval_shape(H.trainer(API_CONFIG).init, jax.random.PRNGKey(0))
    state = jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), shapes)
    return jax.tree.map(lambda x: jnp.stack([x, x]), state) if stacked else state


class StateCase(NamedTuple):
    tree: str  # "params" (theta, omega) or "imagination_params" (w)
    leaf: int  # which leaf (modulo their number)
    change: str  # "grow", "shrink", "add_axis", "drop_axis", "missing", "extra"


STATE_CASES = st.builds(
    StateCase,
    st.sampled_from(("params", "imagination_params")),
    st.integers(0, 10**6),
    st.sampled_from(("grow", "shrink", "add_axis", "drop_axis", "missing", "extra")),
)


def damaged_state(case: StateCase):
    """api_state() with one leaf of one parameter tree reshaped, removed, or one added; and
    that leaf's path as make_act names it."""
    from flax import traverse_util

    state = api_state()
    flat = traverse_util.flatten_dict(getattr(state, case.tree))
    key = sorted(flat)[case.leaf % len(flat)]
    leaf, shape = flat[key], list(flat[key].shape)
    if case.change == "missing":
        del flat[key]
    elif case.change == "extra":
        key = (*key[:-1], "extra")
        flat[key] = jnp.zeros((3,))
    elif case.change in ("grow", "shrink"):
        axis = case.leaf % len(shape)
        shape[axis] += 1 if case.change == "grow" or shape[axis] == 1 else -1
        flat[key] = jnp.zeros(shape, leaf.dtype)
    else:
        flat[key] = jnp.zeros((*shape, 1) if case.change == "add_axis" else shape[:-1], leaf.dtype)
    path = case.tree + "".join(f"[{k!r}]" for k in key)
    return state._replace(**{case.tree: traverse_util.unflatten_dict(flat)}), path


def check_damaged_state_refused(case: StateCase) -> None:
    """make_act refuses a state whose parameters do not match the Config, in one line naming
    the leaf, before anything acts."""
    state, path = damaged_state(case)
    try:
        evaluate_module.make_act(API_CONFIG, state)
    except ValueError as e:
        line = one_line(e)
    else:
        raise AssertionError(f"make_act took a state with {path} {case.change}")
    assert line.startswith("make_act: the state's parameters do not match the config"), line
    assert path in line, (path, line)


BAD_SEEDS = st.one_of(
    st.floats(),
    st.booleans(),
    st.text(max_size=3),
    st.none(),
    st.sampled_from((np.float32(0), np.float64(1), np.bool_(False), 1j, [0], (1,), b"0", np.array(0.0))),
)


def check_bad_seed_refused(case, folder: Path) -> None:
    """make_act (a state of two seeds) and experiments.load refuse a seed that is not an int
    in one line, before they index the state or read the run."""
    import experiments
    from experiments.errors import UserError

    seed, where = case
    try:
        if where == "make_act":
            if seed is None:
                seed = 0.0  # None means 'one seed' to make_act
            evaluate_module.make_act(API_CONFIG, api_state(stacked=True), seed=seed)
        else:
            experiments.load(folder, seed=seed)
    except (ValueError, UserError) as e:
        line = one_line(e)
    else:
        raise AssertionError(f"{where} took seed {seed!r}")
    assert f"{where if where == 'make_act' else 'load'}: seed must be an int" in line, line


SEED_CASES = st.tuples(BAD_SEEDS, st.sampled_from(("make_act", "load")))


def test_make_act_refuses_any_state_that_does_not_match_the_config_and_any_seed_not_an_int(tmp_path):
    passes(STATE_CASES, check_damaged_state_refused, 12)
    (tmp_path / "run.json").write_text("{}")  # never read: the seed is refused first
    passes(SEED_CASES, lambda case: check_bad_seed_refused(case, tmp_path), 12)


def test_mutation_state_fuzz_fails_with_the_checks_undone(monkeypatch, tmp_path):
    """`check_agent_params` a no-op: every damaged state is taken; `_check_seed` the identity:
    a float or bool seed reaches JAX's indexing (make_act's cases fail)."""
    with monkeypatch.context() as m:
        m.setattr(evaluate_module, "check_agent_params", lambda *args: None)
        assert len(fuzz(STATE_CASES, check_damaged_state_refused, 12)) == 12
    monkeypatch.setattr(evaluate_module, "_check_seed", lambda seed, where: seed)
    make_act_only = st.tuples(BAD_SEEDS, st.just("make_act"))
    assert len(fuzz(make_act_only, lambda case: check_bad_seed_refused(case, tmp_path), 12)) == 12
