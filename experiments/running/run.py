"""A run: one arm trained over seeds s_1..s_N in one folder, the one format `train` and `sweep` write.

`train` is a run of one seed; a sweep is one run per arm (in `methods/<arm>/`). What a run
folder holds, and how each file is read, is `experiments.rundir`'s (the format, in one
module); this module writes them in order, and adds what the program records through its
recorders (`Recorder`: train's metrics.jsonl/csv and tracking). `Run.train` continues from the last intact checkpoint (a kill at any point
costs at most a chunk, which runs again to the same numbers), `Run.extend` makes it longer,
`Run.test` writes results.json, `Run.load` reads a finished run back.

One seed runs the unvmapped program (`jax.jit(trainer.run)`): a seed vmapped alone rounds
differently (docs/design.md), and so `train --seed i` gives the numbers it always gave;
several seeds run vmapped in one program, spread over the local devices.
"""

from __future__ import annotations

import dataclasses
import functools
import sys
import time
from pathlib import Path
from typing import Any, Callable, Optional, Protocol, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from experiments import errors
from experiments.reporting.report import DIAGNOSTICS, TARGET_DIAGNOSTICS
from experiments.running import checkpoint, devices, loop, numerics, selection
from experiments import rundir
from experiments.running.presets import Schedule
from foresit_jax.config import Config
from foresit_jax.evaluate import agent_params
from foresit_jax.train import make_trainer, seeds_runner

# run.json's "format": 2 is this one. A `train` folder written before (run.json with one
# "seed", best/ and validation.jsonl) still reads (`models`, evaluate), but does not resume.
RUN_FORMAT = 2

# What each seed trained on, summed over its updates (results.json, `counts`): the frames
# that entered the loss and the episodes that ended, so that arms of different rollout
# layouts or budgets can be compared at equal experience (docs/mechanism.md, Study 8).
COUNTS = ("frames/useful", "charts/episodes")


class Recorder(Protocol):
    """What a program records beside a run's own files (train: its metrics rows, tracking)."""

    def resume(self, done: int) -> None:
        """The run continues after update `done` (0: from the start): forget what was recorded after it."""

    def record(self, chunk: loop.Chunk, validations: list[dict]) -> None:
        """A chunk's metrics ({name: [seeds, n]}) and each seed's validation ({"update", SR, SPL, ...});
        called before the chunk's checkpoint, so that a kill between the two repeats the chunk."""


def counts_of(progress: dict, i: int) -> dict:
    """Seed i's `COUNTS` summed over its training; empty where some chunk went unrecorded
    (a sweep begun before they were kept and resumed since), rather than an undercount."""
    counts = progress.get("counts", {})
    chunks = len(progress["curves"])
    return {
        name: float(np.sum([chunk[i] for chunk in counts[name]]))
        for name in COUNTS
        if len(counts.get(name, ())) == chunks
    }


def rewind(progress: dict, step: int) -> dict:
    """`progress` (a run's progress.json) as it was after update `step`, a chunk's end
    (for a resume whose newer checkpoints are corrupt): the chunks after it are dropped,
    and each seed's best model is chosen again from its validations up to `step`."""
    lengths = np.cumsum([len(c[0]) if c else 0 for c in progress["curves"]])
    chunks = int(np.searchsorted(lengths, step, side="right"))
    history = [[h for h in seed_history if h["update"] <= step] for seed_history in progress["history"]]
    best = [selection.Selection() for _ in history]
    for b, seed_history in zip(best, history):
        for h in seed_history:
            b.offer(h["SR"], h["update"])
    diagnostics, counts = (
        {name: chunks_[:chunks] for name, chunks_ in progress.get(kind, {}).items()}
        for kind in ("diagnostics", "counts")
    )
    return {
        **progress,
        "done": step,
        "history": history,
        "curves": progress["curves"][:chunks],
        "diagnostics": diagnostics,
        "counts": counts,
        "best_sr": [b.sr for b in best],
        "best_update": [b.update for b in best],
        "numerics": numerics.rewind(progress.get("numerics"), step),
    }


def initial_states(trainer, seeds: Sequence[int]):
    """(the seeds' training states, stacked; the selected models (`AgentParams`), stacked:
    at first the initial ones): what a run's checkpoints hold, as `checkpoint.restore` needs
    it. One seed is initialised unvmapped (as `train` always was) and given the seed axis."""
    select = functools.partial(
        agent_params, sigma2_max=trainer.config.sigma2_max, evaluation_noise=trainer.config.evaluation_noise
    )
    if len(seeds) == 1:
        state = trainer.init(selection.run_key(seeds[0]))
        return jax.tree.map(lambda x: x[None], (state, select(state)))
    states = jax.vmap(trainer.init)(jnp.stack([selection.run_key(s) for s in seeds]))
    return states, jax.vmap(select)(states)


def seeds_params(config: Config, states):
    """The `AgentParams` each seed's training state acts with at evaluation (its
    `evaluation_noise`), for states stacked over seeds."""
    return jax.vmap(lambda s: agent_params(s, config.sigma2_max, config.evaluation_noise))(states)


def check_continuable(folder: Path) -> None:
    """Refuse (one line) to train on a finished run folder that cannot continue: one
    assembled from other sweeps' seeds (`sweeps.assemble` keeps no progress.json), or one
    without the checkpoint of its last update (a folder kept without checkpoints, as docs/data's)."""
    if rundir.read_results(folder) is None:
        return
    where = f"{folder.name} in {folder.parent.parent}" if rundir.in_sweep(folder) else str(folder)
    progress = rundir.read_progress(folder)
    if progress is None:
        raise errors.UserError(
            f"{where} was assembled from other sweeps' seeds (--reuse) and keeps no progress to "
            "continue from; extend those sweeps and assemble it again"
        )
    done = progress["done"]
    if not rundir.checkpoint_at(folder, done).is_dir():
        raise errors.UserError(f"{where} keeps no checkpoint of its update {done} to continue from")


def set_aside(folder: Path, updates: int) -> None:
    """Keep a run's results.json of `updates` updates as `results_<updates>_updates.json`
    before it trains on (an extended run); one that keeps no progress.json to continue
    from (assembled), or whose name is taken, is refused in one line."""
    kept = folder / rundir.kept_results(updates)
    check_continuable(folder)
    if kept.exists():
        raise errors.UserError(
            f"{folder} holds both {rundir.RESULTS_FILE} and {kept.name}, both of {updates} updates; move one of them first"
        )
    (folder / rundir.RESULTS_FILE).rename(kept)
    print(f"{folder.name}: its {updates}-update results are kept as {kept.name}; it trains on", flush=True)


@dataclasses.dataclass
class Training:
    """What `Run.train` carries from one chunk to the next (`Run.resume` makes it): the
    environment's parameters, the chunk's program (`run(states, env_params, n) -> (states,
    metrics [seeds, n])`), the seeds' evaluation parameters of the states (`seed_params`,
    stacked over the seeds) and the states as checkpointed (`stacked`), the states, each
    seed's selection, progress.json's contents, the checkpoint manager and the label."""

    env_params: Any
    run: Callable
    seed_params: Callable
    stacked: Callable
    states: Any
    best: list
    progress: dict
    manager: Any
    label: str


@dataclasses.dataclass
class Run:
    """The seeds `seeds` of one arm (`config`, `schedule`) in `folder`; `label` names the
    arm in messages and on the progress bar, `preset` is recorded in run.json."""

    folder: Path
    config: Config
    schedule: Schedule
    seeds: tuple[int, ...]
    label: str = ""
    preset: str = ""

    def __post_init__(self):
        self.folder = Path(self.folder)
        self.seeds = tuple(int(s) for s in self.seeds)
        if not self.seeds:
            raise errors.UserError("a run needs at least one seed")

    # ------------------------------------------------------------------ its files
    def info(self) -> dict:
        """What run.json records."""
        return {
            "format": RUN_FORMAT,
            "arm": self.label or self.config.method,
            "method": self.config.method,
            "preset": self.preset,
            "seeds": list(self.seeds),
            "config": dataclasses.asdict(self.config),
            "schedule": dataclasses.asdict(self.schedule),
            "selection_protocol": selection.PROTOCOL_VERSION,
        }

    def results(self) -> dict | None:
        """results.json when the run has finished its `config.num_updates` updates, else None."""
        done = rundir.read_results(self.folder)
        return done if done is not None and done["updates"] >= self.config.num_updates else None

    def progress(self) -> dict:
        """progress.json, or that of a run not yet started."""
        progress = rundir.read_progress(self.folder)
        if progress is not None:
            return progress
        n = len(self.seeds)
        return {
            "done": 0,
            "best_sr": [-1.0] * n,
            "best_update": [None] * n,
            "history": [[] for _ in self.seeds],
            "curves": [],
            "selection_protocol": selection.PROTOCOL_VERSION,
        }

    def manager(self):
        return checkpoint.checkpoint_manager(rundir.checkpoint_at(self.folder), self.schedule.keep_checkpoints)

    def extend(self, num_updates: int, keep: Sequence[str] = ()) -> "Run":
        """This run made one of `num_updates` updates, to be trained on by `train` (from its
        checkpoint: nothing in training depends on the total, so where its updates are a
        whole number of chunks it ends as a run of `num_updates` from the start would). A
        finished run's results.json is kept as results_<n>_updates.json (`set_aside`), and the
        files of the folder named in `keep` (a program's report) move into report_<n>_updates/.
        Refused in one line, before anything moves: fewer updates than it has, a run that
        cannot continue, or a report already kept there."""
        had = self.config.num_updates
        if num_updates < had:
            raise errors.UserError(
                f"--num-updates {num_updates} would shorten {self.folder} ({had} updates); a run can "
                "only be extended (or trained anew in another --out)"
            )
        if num_updates == had:
            return self
        check_continuable(self.folder)
        kept = self.folder / rundir.kept_report(had)
        moved = [self.folder / name for name in keep if (self.folder / name).is_file()]
        # (a file kept there already with the same bytes is this report, kept by an extension killed part-way)
        taken = [
            f"{kept.name}/{path.name}"
            for path in moved
            if (kept / path.name).exists() and (kept / path.name).read_bytes() != path.read_bytes()
        ]
        finished = rundir.read_results(self.folder)
        if finished is not None:
            kept_results = rundir.kept_results(finished["updates"])
            taken += [kept_results] * (self.folder / kept_results).exists()
        if taken:
            raise errors.UserError(f"{self.folder} already holds {', '.join(taken)}; move them first")
        for path in moved:
            kept.mkdir(exist_ok=True)
            path.replace(kept / path.name)
        if had % self.schedule.chunk_updates and self.progress()["done"] == had:
            print(
                f"warning: {self.folder} has {had} updates, not a whole number of chunks ({self.schedule.chunk_updates}): "
                f"extended, it validates at {had}, where a run of {num_updates} from the start does not, so it will "
                "not end as one",
                file=sys.stderr,
                flush=True,
            )
        longer = dataclasses.replace(self, config=dataclasses.replace(self.config, num_updates=num_updates))
        if rundir.is_run(self.folder):
            previous = rundir.read_json(self.folder / rundir.RUN_FILE)
            rundir.write_run_info(self.folder, {**longer.info(), "commits": previous.get("commits", [])})
        if finished is not None:
            set_aside(self.folder, finished["updates"])
        return longer

    # ------------------------------------------------------------------ training
    def train(self, evaluator, bar, budget: Optional[list] = None, recorders: Sequence[Recorder] = ()) -> bool:
        """Train the seeds to `config.num_updates` from where the folder stopped, selecting each
        seed's model on validation after every chunk; True when done, False when `budget`
        (a one-item list of the chunks this invocation may still run, or [None]) ran out
        first. After each chunk: the recorders, then a checkpoint of the states and the
        selected models, then progress.json. `bar` is `progress.progress_bar`'s, over every
        update it counts (a sweep's bar counts all its arms).

        The run loop, per chunk: learn, check, validate and select (`chunk`), then record and
        checkpoint (`record`), from what `resume` restored."""
        training = self.resume(bar, recorders)
        for n in loop.chunk_sizes(
            training.progress["done"], self.config.num_updates, self.schedule.chunk_updates, budget
        ):
            chunk, validations = self.chunk(training, evaluator, n)
            self.record(training, chunk, validations, bar, recorders)
        return training.progress["done"] >= self.config.num_updates

    def resume(self, bar, recorders: Sequence[Recorder] = ()) -> "Training":
        """The folder made ready to train on (run.json written, a finished run's results set
        aside if it was extended), and what training carries from chunk to chunk restored from
        its last intact checkpoint (fresh states when it has none)."""
        config, seeds, folder = self.config, list(self.seeds), self.folder
        label = f"{self.label}: " if self.label else ""
        finished = rundir.read_results(folder)
        if finished is not None and finished["updates"] < config.num_updates:
            set_aside(folder, finished["updates"])  # extended, killed before it trained on
        folder.mkdir(parents=True, exist_ok=True)
        if len(seeds) == 1 and not rundir.is_run(folder) and rundir.read_progress(folder) is not None:
            print(
                f"warning: {label}{folder} was started by a version that ran a seed alone vmapped; it continues with "
                "the unvmapped program train runs, which rounds differently, so it will not end with the numbers of "
                "either",
                file=sys.stderr,
                flush=True,
            )
        previous = rundir.read_json(folder / rundir.RUN_FILE) if rundir.is_run(folder) else None
        info = rundir.with_commit(self.info(), previous)
        if previous != rundir.jsonable(info):
            rundir.write_run_info(folder, info)
        trainer = make_trainer(config)
        states, best_params = initial_states(trainer, seeds)
        select = functools.partial(agent_params, sigma2_max=config.sigma2_max, evaluation_noise=config.evaluation_noise)
        manager = self.manager()
        progress = self.progress()  # its protocol: checked by the program (`selection.check_resumable`)
        # A kill between a chunk's checkpoint and its progress.json leaves a newer checkpoint
        # that nothing else records: it is dropped, and that chunk runs again (to the same result).
        intact = loop.resume_point(manager, rundir.checkpoint_at(folder), progress["done"], label=label)
        if intact != progress["done"]:
            progress = rewind(progress, intact)
        # The platform of the updates still to come (experiments.running.numerics).
        progress["numerics"], warning = numerics.extend(progress.get("numerics"), progress["done"])
        if warning:
            print(f"warning: {label}{warning}", file=sys.stderr, flush=True)
        if progress["done"]:
            restored = checkpoint.restore(manager, progress["done"], {"states": states, "best": best_params})
            states, best_params = restored["states"], restored["best"]
            print(f"{label}resuming {folder} from update {progress['done']}", flush=True)
            bar.skip(bar.position() + progress["done"])
        for recorder in recorders:
            recorder.resume(progress["done"])
        best = [
            selection.Selection(sr, update, devices.seed_slice(best_params, i))
            for i, (sr, update) in enumerate(zip(progress["best_sr"], progress["best_update"]))
        ]
        # With the bar shown, the chunk moves it after every update (`Trainer.run`'s on_update;
        # the state's update count is this run's, the bar may count several runs').
        offset = bar.position() - progress["done"]
        on_update = (lambda update: bar.at(offset + np.max(update))) if bar.enabled else None
        if len(seeds) == 1:  # the unvmapped program, the seed axis outside it
            states = jax.tree.map(lambda x: x[0], states)
            jitted = jax.jit(functools.partial(trainer.run, on_update=on_update), static_argnums=2)

            def run(state, env_params, n):
                state, metrics = jitted(state, env_params, n)
                return state, jax.tree.map(lambda x: x[None], metrics)

            seed_params = lambda states: jax.tree.map(lambda x: x[None], select(states))  # noqa: E731
            stacked = lambda tree: jax.tree.map(lambda x: x[None], tree)  # noqa: E731
        else:
            states = devices.shard_seeds(states, devices.seed_mesh(len(seeds)))
            run = seeds_runner(trainer, on_update) if on_update else trainer.run_seeds
            seed_params, stacked = jax.vmap(select), lambda tree: tree
        return Training(trainer.env_params, run, seed_params, stacked, states, best, progress, manager, label)

    def chunk(self, training: "Training", evaluator, n: int) -> tuple[loop.Chunk, list[dict]]:
        """`n` updates of every seed, checked (a non-finite loss or parameter stops here,
        before anything of the chunk is recorded), then each seed validated and its best
        model kept (`selection`): (the chunk, each seed's validation)."""
        done, started = training.progress["done"], time.time()
        training.states, metrics = training.run(training.states, training.env_params, n)
        metrics = jax.tree.map(np.asarray, metrics)  # [seeds, n]
        warning = loop.check(
            metrics,
            training.states,
            done,
            n,
            manager=training.manager,
            checkpoints=rundir.checkpoint_at(self.folder),
            seeds=list(self.seeds),
            label=training.label,
        )
        chunk = loop.Chunk(metrics, done + n, n, warning, started)
        params_now = training.seed_params(training.states)
        validations = []
        for i, seed in enumerate(self.seeds):
            params = devices.seed_slice(params_now, i)
            val = selection.validate(evaluator, params, self.config, seed, self.schedule.val_episodes_per_room)
            validations.append({"update": chunk.done, **val["overall"]})
            training.best[i].offer(val["overall"]["SR"], chunk.done, params)
        return chunk, validations

    def record(
        self, training: "Training", chunk: loop.Chunk, validations: list[dict], bar, recorders: Sequence[Recorder] = ()
    ) -> None:
        """A chunk recorded (the recorders), then checkpointed (states and selected models),
        then progress.json: a kill between the two repeats the chunk (`Recorder.record`,
        `loop.resume_point`); then the progress bar."""
        metrics, progress = chunk.metrics, training.progress
        for recorder in recorders:
            recorder.record(chunk, validations)
        progress["curves"].append(metrics["charts/success_rate"].tolist())
        for name in filter(metrics.__contains__, DIAGNOSTICS + TARGET_DIAGNOSTICS):  # each seed's mean over the chunk
            progress.setdefault("diagnostics", {}).setdefault(name, []).append(metrics[name].mean(axis=1).tolist())
        for name in COUNTS:  # each seed's total over the chunk
            progress.setdefault("counts", {}).setdefault(name, []).append(metrics[name].sum(axis=1).tolist())
        for h, val in zip(progress["history"], validations):
            h.append(val)
        best_params = jax.tree.map(lambda *x: np.stack(x), *[b.params for b in training.best])
        checkpoint.save(
            training.manager, chunk.done, {"states": training.stacked(training.states), "best": best_params}
        )
        progress.update(
            done=chunk.done, best_sr=[b.sr for b in training.best], best_update=[b.update for b in training.best]
        )
        rundir.write_json(self.folder / rundir.PROGRESS_FILE, progress)
        useful = float(np.sum(metrics["frames/useful"]))  # steps that entered the loss, every seed's
        bar(
            chunk.n,
            {
                **({"method": self.label} if self.label else {}),
                "useful fps": f"{useful / (time.time() - chunk.started):,.0f}",
                "SR": f"{100 * metrics['charts/success_rate'].mean():.1f}%",  # in percent, as everywhere
                "val SR": f"{np.mean([v['SR'] for v in validations]):.1f}%",
                **({"warning": "diverging"} if chunk.warning else {}),
            },
        )

    def test(self, evaluator) -> dict:
        """Test each seed's selected and last model (on the test episodes of its seed, with SR
        and SPL by path length) and write results.json; returns it. The run must have trained
        to its end (`train`)."""
        progress = self.progress()
        if progress["done"] < self.config.num_updates:
            raise errors.UserError(
                f"{self.folder} has trained {progress['done']} of {self.config.num_updates} updates; "
                "train it to the end first (--resume)"
            )
        trainer, states, best = self.load_checkpoint(progress["done"])
        last_params = self._params_of(trainer, states)
        curves = np.concatenate([np.array(c, float) for c in progress["curves"]], axis=1)
        results = []
        for i, seed in enumerate(self.seeds):
            chosen, last = devices.seed_slice(best, i), devices.seed_slice(last_params, i)
            test = [
                evaluator.evaluate(
                    p,
                    self.config,
                    "test",
                    selection.test_key(seed),
                    self.schedule.test_episodes_per_room,
                    by_length=True,
                )
                for p in (chosen, last)
            ]
            results.append(
                {
                    "seed": seed,
                    "selected_update": progress["best_update"][i],
                    "selected": test[0],
                    "last": test[1],
                    "validation": progress["history"][i],
                    "training_success_rate": curves[i].tolist(),
                    "diagnostics": {
                        name: [chunk[i] for chunk in chunks] for name, chunks in progress.get("diagnostics", {}).items()
                    },
                    "numerics": progress.get("numerics"),
                    "counts": counts_of(progress, i),
                }
            )
        done = {
            "updates": progress["done"],
            "results": results,
            "curves": curves.tolist(),
            "selection_protocol": progress.get("selection_protocol", selection.PROTOCOL_VERSION),
        }
        rundir.write_json(self.folder / rundir.RESULTS_FILE, done)
        return rundir.read_results(self.folder)  # as written (NaN as None)

    # ------------------------------------------------------------------ reading back
    def _params_of(self, trainer, states):
        return seeds_params(trainer.config, states)

    def load_checkpoint(self, step: int, seeds: Sequence[int] | None = None):
        """(trainer, the seeds' training states, their selected models) of checkpoint `step`,
        stacked over `seeds` (the run's, unless given: a finished run's in results' order)."""
        if not rundir.checkpoint_at(self.folder, step).is_dir():  # before orbax's manager makes checkpoints/
            raise errors.UserError(
                f"{self.folder} has lost its checkpoint of update {step} (checkpoints/{step} is not "
                "there: deleted or moved); put it back, or train the run anew"
            )
        trainer = make_trainer(self.config)
        # the checkpoint's shapes only (`eval_shape`: nothing runs; initialising for real ran
        # the networks' init op by op, hundreds of small compilations per method)
        states, best = jax.eval_shape(lambda: initial_states(trainer, list(seeds or self.seeds)))
        restored = checkpoint.restore(
            self.manager(),
            step,
            {"states": states, "best": best},
        )
        return trainer, restored["states"], restored["best"]

    def load(self):
        """A finished run read back: (trainer, the seeds' last training states, their selected
        models), stacked over the seeds it finished (`rundir.finished_seeds`, in its results' order)
        on the first local device."""
        done = rundir.read_results(self.folder, required=True)["updates"]
        return self.load_checkpoint(done, rundir.finished_seeds(self.folder))


def is_legacy_train_folder(info: dict) -> bool:
    """Whether run.json is that of a `train` folder from before runs had one format (`RUN_FORMAT`)."""
    return "format" not in info


def read(folder: Path) -> Run:
    """The run a folder's run.json describes (one of this format: `RUN_FORMAT`)."""
    info = rundir.read_run_info(folder)
    if is_legacy_train_folder(info):
        raise errors.UserError(
            f"{folder} was written by experiments.train before runs had one format (it keeps best/ "
            "and validation.jsonl): evaluate, probe and failures read it, but it cannot be trained "
            "on; train it anew into another --out"
        )
    return Run(
        folder,
        Config(**info["config"]),
        Schedule(**info["schedule"]),
        tuple(info["seeds"]),
        info.get("arm", ""),
        info.get("preset", ""),
    )
