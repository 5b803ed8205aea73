"""Train one agent: `python -m experiments.train --method a3c+foresit --preset quick --seed 0 --out runs/x`.

A run of one seed (`experiments.running.run.Run`: the folder format a sweep's arms have too):
shows a progress bar (updates, frames/s, success rate, ETA); validates after each chunk of
updates and keeps the model with the best validation SR (model selection); checkpoints the
training state and that model after each chunk (checkpoints/, progress.json); at the end
tests the selected and the last model (results.json). Beside them it writes a row of
metrics per update (metrics.jsonl and .csv, and TensorBoard or W&B with --track) and, at the
end, the selected model's test results beside the random policy's (results_test.json and
.md) and a learning-curve PNG.

`--resume` continues an interrupted run from its last intact checkpoint (a corrupt one is
skipped, saying so) and ends bit-identical to an uninterrupted run with the same seed on the
same platform (progress.json records the platform of each stretch of updates, and a resume
on another one warns: `experiments.running.numerics`). With `--resume`, `--num-updates`
beyond the run's extends it (`Run.extend`; the earlier report is kept in
report_<n>_updates/); any other flag that differs from the run's is refused
(`resume_conflicts`); a finished run is left as it is. An existing run folder is never
overwritten without `--resume` or `--overwrite`, and one process at a time writes it
(`rundir.claim`). A run folder written by train before this format (best/,
validation.jsonl) still reads (evaluate, probe, failures, cvae_compare) but does not resume.

Parameters and optimiser state are checked finite before every checkpoint: a run that
produced NaN or inf stops with an error naming its last finite checkpoint; a loss or
gradient norm far out of range, or a collapsed entropy, is warned of (`loop.divergence`).
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path
from typing import Literal, Optional

import numpy as np

from experiments import errors
from experiments.reporting import figures, tables
from experiments.running import flags, loop, presets, selection, tracking
from experiments import rundir
from experiments.running.presets import TrainConfigFields, check_seeds, check_sizes, config_flag, given, preset
from experiments.running.progress import progress_bar
from experiments.running.run import Run, read
from foresit_jax.evaluate import Evaluator


@dataclasses.dataclass(frozen=True)
class Args:
    """Train one ForeSIT (or baseline) agent."""

    method: presets.MethodFlag = "a3c+foresit"
    setup: presets.SetupFlag = "savn"
    preset: presets.PresetFlag = "quick"
    seed: int = 0
    """Random seed (same seed, same result, bit for bit, on the same machine)."""
    out: Path = Path("runs/x")
    """Run folder."""
    resume: flags.Resume = False
    overwrite: flags.Overwrite = False
    num_updates: flags.NumUpdates = None
    chunk_updates: Optional[int] = None
    """Override the preset's updates per chunk (checkpoint/validation interval)."""
    test_episodes_per_room: flags.TestEpisodes = None
    val_episodes_per_room: flags.ValEpisodes = None
    stop_after_chunks: flags.StopAfterChunks = None
    progress: flags.Progress = True
    allow_large: flags.AllowLarge = False
    track: Literal["none", "tensorboard", "wandb"] = "none"
    """Also log the metrics and validations to TensorBoard (<out>/tensorboard) or Weights & Biases
    (offline without WANDB_API_KEY, <out>/wandb); needs pip install 'foresit_jax[track]'."""
    config: config_flag(TrainConfigFields) = dataclasses.field(default_factory=TrainConfigFields)
    """Every other Config field, e.g. --learning-rate 3e-4 --num-lanes 16 --gamma 0.9 --room-types bathroom: the
    preset's value (or the arm's, METHOD@field=value) unless given; one the arm sets otherwise is refused."""


def build(args: Args):
    """Config and Schedule from the arguments (or from the run folder when resuming)."""
    check_seeds(args.seed)
    config, schedule = preset(
        args.preset, args.method, num_updates=args.num_updates, setup=args.setup, **given(args.config)
    )
    sched = {k: getattr(args, k) for k in ("chunk_updates", "test_episodes_per_room", "val_episodes_per_room")}
    schedule = dataclasses.replace(schedule, **{k: v for k, v in sched.items() if v is not None})
    for name in ("chunk_updates", "test_episodes_per_room", "val_episodes_per_room"):
        if getattr(schedule, name) < 1:
            raise ValueError(f"{name} must be >= 1, got {getattr(schedule, name)}")
    check_sizes(config, schedule=schedule, allow_large=args.allow_large)
    return config, schedule


def run_flags(info: dict) -> dict:
    """The values a run (its run.json, `info`) has for train's own flags."""
    config, schedule = info["config"], info["schedule"]
    return {
        "method": info["arm"],
        "setup": config["setup"],
        "preset": info["preset"],
        "seed": info["seeds"][0],
        **{k: schedule[k] for k in ("chunk_updates", "test_episodes_per_room", "val_episodes_per_room")},
    }


def resume_conflicts(args: Args, info: dict) -> list[str]:
    """The flags given with --resume (those not at their defaults: one at its default
    cannot be told from one not given) whose values differ from the run's, as
    `--flag value (the run has ...)`; --num-updates is not one (it extends the run)."""
    config, run = info["config"], run_flags(info)
    defaults = Args()
    clash = [
        f"--{k.replace('_', '-')} {getattr(args, k)} (the run has {v})"
        for k, v in run.items()
        if getattr(args, k) != getattr(defaults, k) and getattr(args, k) != v
    ]
    return clash + [
        f"--{k.replace('_', '-')} {v} (the run has {config[k]})"
        for k, v in given(args.config).items()
        if rundir.jsonable(v) != config[k]
    ]


def resume_ignored(args: Args, info: dict) -> list[str]:
    """The flags written on the command line at their defaults (`errors.given_flags`)
    whose values differ from the run's: --resume ignores them, saying so."""
    run = run_flags(info)
    defaults = Args()
    return [
        f"--{k.replace('_', '-')} {getattr(args, k)} (the run has {v})"
        for k, v in run.items()
        if k in errors.given_flags() and getattr(args, k) == getattr(defaults, k) != v
    ]


class Metrics:
    """train's recorder (`run.Recorder`): a row per update (metrics.jsonl and .csv, with
    running totals: `rundir.metric_rows`) and the tracker's rows (metrics, and each
    validation under `validation/`)."""

    def __init__(self, out: Path, tracker, rows: list[dict]):
        self.out, self.tracker, self.rows, self.last_row = out, tracker, rows, None  # rows: those in the folder

    def resume(self, done: int) -> None:
        rows = [r for r in self.rows if r["update"] <= done]  # not those written after the checkpoint it continues from
        rundir.truncate_rows(self.out / "metrics", done, rows)
        self.last_row = rows[-1] if rows else None

    def record(self, chunk: loop.Chunk, validations: list[dict]) -> None:
        rows = rundir.metric_rows({k: v[0] for k, v in chunk.metrics.items()}, chunk.done - chunk.n, self.last_row)
        self.last_row = rows[-1]
        rundir.append_rows(self.out / "metrics", rows)
        self.tracker.log(rows)
        self.tracker.log(validations, prefix="validation/")


def start(args: Args) -> tuple[Run, bool]:
    """The run of --out, checked and ready to train (new, or resumed and perhaps extended:
    `Run.extend`), and whether it was resumed."""
    out = args.out
    if not args.resume:
        # Validate the arguments before touching --out (with --overwrite, a typo must not
        # delete the existing run and then fail).
        config, schedule = build(args)
        rundir.prepare_run_dir(out, resume=False, overwrite=args.overwrite)
        run = Run(out, config, schedule, (args.seed,), args.method, args.preset)
        rundir.write_run_info(out, run.info())
        return run, False
    rundir.prepare_run_dir(out, resume=True, overwrite=args.overwrite)
    run = read(out)  # refuses a folder of before `run.RUN_FORMAT`, in one line
    if len(run.seeds) != 1 or rundir.in_sweep(out):
        raise errors.UserError(
            f"{out} is a sweep's arm ({len(run.seeds)} seed(s)); continue its sweep with "
            "experiments.sweep --resume --out <the sweep folder>"
        )
    info = rundir.read_run_info(out)
    selection.check_resumable(run.progress().get("selection_protocol"), str(out))
    clash = resume_conflicts(args, info)
    if clash:
        raise errors.UserError(
            f"--resume continues {out} with its own settings; drop {', '.join(clash)} "
            "(only --num-updates may differ: it extends the run)"
        )
    errors.say_ignored(resume_ignored(args, info), out)
    if args.num_updates is not None and args.num_updates != run.config.num_updates:
        check_sizes(dataclasses.replace(run.config, num_updates=args.num_updates), allow_large=args.allow_large)
        had = run.config.num_updates
        kept = out / f"report_{had}_updates"
        run = run.extend(args.num_updates, keep=REPORT_FILES)
        print(
            f"extending {out} to {run.config.num_updates} updates (it had {had})"
            + (f"; its {had}-update report is kept in {kept.name}/" if kept.is_dir() else "")
        )
    return run, True


# What train writes at the end beside results.json (an extension keeps the earlier ones).
REPORT_FILES = ("results_test.json", "results_test.md", "learning_curve.png")


def main(args: Args) -> dict:
    out = args.out
    flags.check_stop_after_chunks(args.stop_after_chunks)
    tracking.check(args.track)
    run, resumed = start(args)
    config, seed = run.config, run.seeds[0]
    if resumed and run.results() is not None and (out / "results_test.json").is_file():
        print(
            f"{out} is finished ({config.num_updates} updates) and its results are written; nothing to do "
            "(pass --num-updates N to extend it)"
        )
        return rundir.read_json(out / "results_test.json")["results"]
    evaluator = Evaluator.for_config(config)  # held for the run: validation compiles once
    t_start = time.time()
    if run.results() is None:
        rows = rundir.read_rows(out / "metrics")  # a damaged file is named here, before anything starts
        tracker = tracking.make(args.track, out, f"{config.method} seed {seed}", run.info()["config"])
        metrics = Metrics(out, tracker, rows)
        bar = progress_bar(config.num_updates, 0, args.progress)
        with loop.interruptible() as stop:  # a first Ctrl-C stops after the current chunk
            finished = run.train(evaluator, bar, [args.stop_after_chunks], [metrics])
        bar(0, None)
        tracker.close()
        if not finished:
            done = run.progress()["done"]
            if stop.requested:
                print(f"interrupted at update {done}; continue with --resume", flush=True)
            else:
                print(f"stopped after {args.stop_after_chunks} chunks at update {done} (resume with --resume)")
            return {"stopped_at": done}
        done = run.test(evaluator)
    else:  # killed after results.json, before the report
        done = run.results()
    return report(run, done, evaluator, time.time() - t_start)


def report(run: Run, done: dict, evaluator, seconds: float) -> dict:
    """train's report of a finished run of one seed: results_test.json and .md (the selected
    model's test results, beside the uniformly random policy's on the same episodes) and
    learning_curve.png (training SR, smoothed, and the validations)."""
    out, config, seed = run.folder, run.config, run.seeds[0]
    (result,) = done["results"]
    step = result["selected_update"]
    test = {room: m for room, m in result["selected"].items() if room != "by_length"}
    random = evaluator.evaluate_random_policy(
        config, "test", selection.test_key(seed), run.schedule.test_episodes_per_room
    )
    rundir.write_json(out / "results_test.json", {"selected_update": step, "results": test, "random_policy": random})
    title = (
        f"{tables.arm_label(config.method)}, preset {run.preset}, seed {seed}: test split (model of update {step}, "
        "best validation SR)"
    )
    text = (
        tables.results_markdown(test, title)
        + "\n"
        + tables.results_markdown(random, "Uniformly random policy, same rooms", level=2)
    )
    (out / "results_test.md").write_text(text)
    y = np.array(result["training_success_rate"], float)
    vals = [(v["update"], v["SR"] / 100.0) for v in result["validation"]]
    figures.learning_curve_png(
        out / "learning_curve.png", {config.method: (np.arange(1, len(y) + 1), figures.smooth(y))}, val_points=vals
    )
    print(text)
    print(f"wrote {out}/results_test.md, results_test.json, learning_curve.png, metrics.csv ({seconds:.0f} s)")
    note = presets.smoke_note(run.preset, run.schedule, config)  # tiny: say what its numbers are not
    if note:
        print(note)
    return rundir.read_json(out / "results_test.json")["results"]


def cli(argv=None) -> None:
    errors.run_cli(Args, main, argv)


if __name__ == "__main__":
    cli(sys.argv[1:])
