"""A sweep: several arms, each trained over seeds vmapped in one jitted program.

Each arm's seeds run vmapped inside one jitted program (in chunks, for progress), spread
over the local devices along the seed axis (experiments.running.devices).  The protocol is
`train`'s (experiments.running.selection): seed i of the sweep is seed `seed + i`,
initialised from the key `train --seed <seed + i>` uses; after each chunk each seed is
validated on the episodes that run would validate on, and the model with the best
validation SR is the one tested, on that run's test episodes: each arm is a
`experiments.running.run.Run` of the sweep's seeds, the folder format train's run of one
seed has.  So a seed's numbers are those of its `train` run with the same preset and
schedule (exactly, in a sweep of one seed, which runs train's unvmapped program), up to
the float rounding of a vmapped program (the batched matmuls differ in the last bits);
over many updates that rounding grows into another trajectory (at quick: the same
training curve for the first ~100 updates, then apart), so long runs agree in
distribution, not in value.  The last model is tested too, for comparison.

`run(Sweep(...))` trains (or continues) a sweep and writes its report; `run_method` one
arm's `Run`, resumable after a kill (its progress.json and checkpoints); `copy_finished`
takes arms other sweeps of the same protocol finished (`reuse_sources`), seed by seed;
`load_method` reads a finished arm back. The program `experiments.sweep` is this with flags.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Optional

import jax
import numpy as np

from experiments import errors
from experiments.reporting import figures
from experiments.reporting.report import (
    by_length_markdown,
    diagnostics_markdown,
    paired_markdown,
    selection_markdown,
    table,
    table_markdown,
)
from experiments import rundir
from experiments.running import checkpoint, devices, flags, loop, numerics, presets, selection
from experiments.running.run import Run, check_continuable, set_aside
from experiments.running.presets import (
    MAX_EPISODES,
    SweepConfigFields,
    check_seeds,
    check_sizes,
    config_flag,
    duplicate_arms,
    given,
    normalise_arm,
    preset,
)
from experiments.running.progress import progress_bar
from foresit_jax.evaluate import Evaluator


@dataclasses.dataclass(frozen=True)
class Sweep:
    """What a sweep trains, and where: the arms, the seeds, the protocol (setup, preset,
    overrides) and the folder. sweep, tune and paper run one (`run`); sweep.json records
    it (`rundir.write_started_args`), and the programs that read a sweep folder (probe,
    failures, paper) read it back (`saved`)."""

    methods: presets.MethodsFlag = ("a3c", "a3c+foresit")
    setup: presets.SetupFlag = "savn"
    seeds: int = 5
    """Seeds per method (vmapped in one program)."""
    preset: presets.PresetFlag = "quick"
    seed: int = 0
    """Base seed: seed i of a method is the run `train --seed <seed + i>` would make."""
    out: Path = Path("runs/sweep")
    """Output folder."""
    reuse: flags.Reuse = ()
    num_updates: flags.NumUpdates = None
    test_episodes_per_room: flags.TestEpisodes = None
    val_episodes_per_room: flags.ValEpisodes = None
    config: config_flag(SweepConfigFields) = dataclasses.field(default_factory=SweepConfigFields)
    """Every other Config field for every method, e.g. --learning-rate 3e-4: the preset's (or the arm's) unless
    given; one an arm sets otherwise is refused."""


def seeds_of(spec: Sweep) -> list[int]:
    """The seeds of the sweep: those of `train --seed` for each of its runs."""
    return [spec.seed + i for i in range(spec.seeds)]


def method_schedule(method: str, spec: Sweep):
    """The preset's Config and Schedule of `method`, with the sweep's overrides."""
    config, schedule = preset(spec.preset, method, num_updates=spec.num_updates, setup=spec.setup, **given(spec.config))
    sched = {k: getattr(spec, k) for k in ("test_episodes_per_room", "val_episodes_per_room")}
    return config, dataclasses.replace(schedule, **{k: v for k, v in sched.items() if v is not None})


def episodes_per_room(folder: Path, split: str, method: Optional[str] = None, given: Optional[int] = None) -> int:
    """The episodes per room type that `split` ("val" or "test") is evaluated with in a
    run folder (its run.json's schedule) or a sweep folder (`method`'s: the preset's, with
    the sweep's overrides), or `given` (a user's --episodes-per-room) instead; refused
    outside 1..MAX_EPISODES."""
    if given is None:
        key = f"{split}_episodes_per_room"
        if rundir.is_sweep(folder):
            given = getattr(method_schedule(method, saved(folder))[1], key)
        else:
            given = rundir.read_run_info(folder)["schedule"][key]
    if not 1 <= given <= MAX_EPISODES:
        raise errors.UserError(f"--episodes-per-room must lie in 1..{MAX_EPISODES:,}, got {given}")
    return given


# A sweep's arguments that fix what a finished method's results are: a method is reused
# from another sweep only when they agree.  The seeds are not among them: seed s of any
# sweep is the run `train --seed s` makes (the same key, validation and test episodes),
# whichever seeds were vmapped beside it (up to the float rounding of the vmapped program,
# see the module docstring), so seeds of several sweeps combine into one.
PROTOCOL = ("setup", "preset", "num_updates", "test_episodes_per_room", "val_episodes_per_room", "config")


def _protocol_value(spec: Sweep, name: str):
    """What a sweep's `name` of PROTOCOL is, as JSON: the Config fields it set (none for
    a sweep saved before it could set them)."""
    value = rundir.jsonable(getattr(spec, name))
    return {k: v for k, v in value.items() if v is not None} if name == "config" else value


def reuse_sources(spec: Sweep) -> list[Path]:
    """The folders of --reuse, checked: a folder that is not a sweep, one run with another
    protocol, or a finished method selected by another version of `experiments.running.selection`,
    is refused in one line."""
    sources = []
    for folder in map(Path, spec.reuse):  # str when read back from sweep.json by --resume
        if not rundir.is_sweep(folder):
            raise errors.UserError(f"--reuse {folder}: not a sweep folder (no sweep.json)")
        if folder.resolve() == Path(spec.out).resolve():
            raise errors.UserError(f"--reuse {folder}: the sweep being written (--out); to continue it use --resume")
        started = saved(folder)
        clash = [
            f"--{k.replace('_', '-')} {_protocol_value(started, k)} there, {_protocol_value(spec, k)} here"
            for k in PROTOCOL
            if _protocol_value(started, k) != _protocol_value(spec, k)
        ]
        if clash:
            raise errors.UserError(
                f"--reuse {folder}: run with another protocol ({'; '.join(clash)}); "
                "only sweeps of the same protocol can be combined"
            )
        for method in spec.methods:
            found = method_folder(folder, method, spec)
            made = method_protocol(found)
            if (found / rundir.RESULTS_FILE).is_file() and made != selection.PROTOCOL_VERSION:
                raise errors.UserError(
                    f"--reuse {folder}: its {method} was selected by another protocol (version "
                    f"{made}; this code's is {selection.PROTOCOL_VERSION}, experiments/running/selection.py)"
                )
        sources.append(folder)
    return sources


def method_folder(sweep_folder: Path, method: str, spec: Sweep) -> Path:
    """The folder of `method` (an arm) in the sweep `sweep_folder`: the one of that name,
    else the first (in name order) of an arm that trains the same Config under `spec`'s
    protocol, e.g. `a3c` for `a3c@learning_rate=1e-3` at quick, whose learning rate that is
    (so that a tuning grid reuses a sweep of the preset's own values); the folder of that
    name, absent, when none does."""
    own = rundir.arm_folder(sweep_folder, method)
    if own.is_dir():
        return own
    config, _ = method_schedule(method, spec)
    for other in rundir.arm_folders(sweep_folder):
        try:
            if method_schedule(other.name, spec)[0] == config:
                return other
        except ValueError:  # a folder name that is no arm of this code
            continue
    return own


def method_protocol(folder: Path) -> int | None:
    """The version of `experiments.running.selection` a method folder of a sweep was validated
    under: its results.json's (1 where it records none: finished before versions were
    recorded), else its progress.json's (None where it records none: started before they
    were recorded there, and so not known), else None (not started)."""
    for name, unrecorded in ((rundir.RESULTS_FILE, 1), (rundir.PROGRESS_FILE, None)):
        if (folder / name).is_file():
            return rundir.read_json(folder / name).get("selection_protocol", unrecorded)
    return None


def check_started(spec: Sweep) -> None:
    """For --resume, before anything runs: refuse (one line) to continue a sweep whose
    methods so far were validated under another selection protocol."""
    for method in spec.methods:
        folder = rundir.arm_folder(spec.out, method)
        selection.check_resumable(method_protocol(folder), f"{method} in {folder}")


def _seed_ranges(seeds) -> str:
    """'0-1, 4' for [0, 1, 4]."""
    seeds, out = sorted(seeds), []
    for s in seeds:
        if out and s == out[-1][1] + 1:
            out[-1][1] = s
        else:
            out.append([s, s])
    return ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in out)


def copy_finished(spec: Sweep, sources: list[Path]) -> None:
    """Give --out each method of `spec.methods` that it lacks and whose every seed the
    sweeps of `sources` have finished between them: its folder copied whole (checkpoints
    included) from the first source that has exactly these seeds, else assembled seed by
    seed, each from the first source that has it (`assemble`). A method some of whose
    seeds no source has is left to train (all its seeds), and said so. The sources are
    only read; a kill mid-copy leaves no half a method."""
    wanted = seeds_of(spec)
    for method in spec.methods:
        target = rundir.arm_folder(spec.out, method)
        folders = [method_folder(f, method, spec) for f in sources]
        have = {folder: rundir.finished_seeds(folder) for folder in folders}
        if target.exists() or not any(have.values()):
            continue
        partial = target.with_name(f".{method}.copying")
        shutil.rmtree(partial, ignore_errors=True)
        whole = [folder for folder in folders if have[folder] == wanted]
        where = {}  # seed -> the first folder that finished it
        for folder in folders:
            for seed in have[folder]:
                where.setdefault(seed, folder)
        missing = [s for s in wanted if s not in where]
        if whole:
            shutil.copytree(whole[0], partial)
            alias = f" (as {whole[0].name}: the same Config)" if whole[0].name != method else ""
            print(f"{method}: finished in {whole[0].parent.parent}{alias}, copied", flush=True)
        elif not missing:
            parts = {s: where[s] for s in wanted}
            assemble(method, spec, parts, partial)
            taken = "; ".join(
                f"seeds {_seed_ranges([s for s in wanted if parts[s] == f])} from {f.parent.parent}"
                for f in dict.fromkeys(parts.values())
            )
            print(f"{method}: assembled ({taken})", flush=True)
        else:
            found = [s for s in wanted if s in where]
            if found:
                print(
                    f"{method}: seeds {_seed_ranges(found)} are finished in --reuse, but not seeds "
                    f"{_seed_ranges(missing)}, so all {len(wanted)} seeds train here (to reuse them, run the "
                    "missing seeds with --seed/--seeds and add that run to --reuse)",
                    flush=True,
                )
            continue
        partial.rename(target)


def assemble(method: str, spec: Sweep, parts: dict[int, Path], target: Path) -> None:
    """A finished method folder of `spec`'s seeds in `target` (results.json and a
    checkpoint of the seeds' last training states and selected models, stacked in seed
    order), seed s taken from the finished method folder `parts[s]` of another sweep.
    Its results.json records where each seed came from ("assembled_from")."""
    seeds = seeds_of(spec)
    loaded = {}
    for folder in dict.fromkeys(parts.values()):
        done = rundir.read_results(folder)
        *_, states, best = load_method(method, spec, folder)
        loaded[folder] = (done, rundir.finished_seeds(folder), states, best)
    updates = {done["updates"] for done, *_ in loaded.values()}
    protocols = {done.get("selection_protocol") for done, *_ in loaded.values()}
    if len(updates) != 1 or len(protocols) != 1:  # reuse_sources checks both; this guards a hand-edited folder
        raise errors.UserError(
            f"--reuse: {method}'s seeds were trained for {sorted(updates)} updates under selection "
            f"protocol(s) {sorted(protocols, key=str)}; they cannot be combined"
        )
    rows = []  # per seed: (result, curve, states, best)
    for seed in seeds:
        done, order, states, best = loaded[parts[seed]]
        i = order.index(seed)
        rows.append((done["results"][i], done["curves"][i], *jax.tree.map(lambda x: x[i], (states, best))))
    results, curves, states, best = zip(*rows)
    stack = lambda trees: jax.tree.map(lambda *x: np.stack(x), *trees)  # noqa: E731
    (step,) = updates
    target.mkdir(parents=True)
    checkpoint.save(
        checkpoint.checkpoint_manager(rundir.checkpoint_at(target), 2),
        step,
        {"states": stack(states), "best": stack(best)},
    )
    rundir.write_json(
        target / rundir.RESULTS_FILE,
        {
            "updates": step,
            "results": list(results),
            "curves": list(curves),
            "selection_protocol": protocols.pop(),
            "assembled_from": {str(s): str(parts[s]) for s in seeds},
        },
    )


def assembled_markdown(folders: dict[str, Path]) -> str:
    """For a report's "Platforms" section: a line per method (of `folders`: method -> its
    folder in a sweep) whose seeds were assembled from several sweeps (`assemble`), naming
    the folder each seed came from; '' when none was."""
    lines = []
    for method, folder in folders.items():
        done = rundir.read_results(folder) or {}
        where = {}  # source folder -> its seeds
        for seed, source in done.get("assembled_from", {}).items():
            where.setdefault(source, []).append(int(seed))
        if where:
            lines.append(f"- {method}: " + "; ".join(f"seeds {_seed_ranges(s)} from {f}" for f, s in where.items()))
    if not lines:
        return ""
    return (
        "\nSeeds trained in separate sweeps and combined (`--reuse`; seed s is the run `train --seed s` makes "
        "in any of them):\n\n" + "\n".join(lines) + "\n"
    )


def load_method(method: str, spec: Sweep, folder: Path):
    """A finished method of a sweep read back: (Config, trainer, the seeds' last training
    states, their selected models), stacked over the seeds it finished (`rundir.finished_seeds`,
    in its results' order) on the first local device (`Run.load`). `spec` gives the
    protocol, not the seeds."""
    config, schedule = method_schedule(method, spec)
    trainer, states, best = Run(folder, config, schedule, tuple(rundir.finished_seeds(folder)), method).load()
    return config, trainer, states, best


def run_method(method: str, spec: Sweep, bar, evaluator, folder: Path, budget: list) -> tuple | None:
    """Train (or continue, or read back) one arm of the sweep: its `Run` of the sweep's
    seeds in `folder`. Returns (per seed: its results.json entry; updates [n]; training
    success rate [seeds, n]), or None when `budget` (chunks this invocation may still run,
    a one-item list, or [None]) ran out first."""
    config, schedule = method_schedule(method, spec)
    run = Run(folder, config, schedule, tuple(seeds_of(spec)), method, spec.preset)
    done = run.results()
    if done is None:
        if not run.train(evaluator, bar, budget):
            return None
        done = run.test(evaluator)
    else:
        bar(done["updates"], {"method": method})
    return done["results"], np.arange(1, done["updates"] + 1), np.array(done["curves"], float)


def check(spec: Sweep, allow_large: bool = False) -> None:
    """Refuse (one line) a sweep that cannot run, before anything is written or trained:
    no arms, no seeds, an episode count below 1, an arm this code does not know, an arm
    listed twice (however it is spelt: `presets.normalise_arm`), and (unless `allow_large`)
    sizes past `presets.check_sizes`'s bounds."""
    if spec.seeds < 1:
        raise errors.UserError(f"--seeds must be >= 1, got {spec.seeds}")
    if not spec.methods:
        raise errors.UserError("--methods needs at least one method")
    for method in spec.methods:  # each arm is a folder, methods/<arm>: its name must be one
        size = len(os.fsencode(method))
        if size > rundir.NAME_MAX:
            raise errors.UserError(
                f"the arm {method[:40]}... is {size} bytes, longer than the {rundir.NAME_MAX} a folder name can have "
                "(each arm is the folder methods/<arm>); shorten it, e.g. drop the fields at the preset's values"
            )
        if "/" in method or method in (".", ".."):
            raise errors.UserError(f"the arm {method!r} cannot be a folder name (methods/<arm>); write it without '/'")
        rundir.check_path(rundir.arm_folder(spec.out, method))
    for first, again in duplicate_arms(spec.methods):  # the same arm however it is spelt (`normalise_arm`)
        if first == again:
            raise errors.UserError(f"--methods lists {first} more than once; list each arm once")
        raise errors.UserError(
            f"--methods lists {first} and {again}, the same arm ({normalise_arm(first)}); list it once"
        )
    check_seeds(spec.seed, spec.seeds)
    for name in ("test_episodes_per_room", "val_episodes_per_room"):
        if getattr(spec, name) is not None and getattr(spec, name) < 1:
            raise errors.UserError(f"--{name.replace('_', '-')} must be >= 1, got {getattr(spec, name)}")
    for method in spec.methods:  # a ValueError names what is wrong
        config, schedule = method_schedule(method, spec)
        check_sizes(config, spec.seeds, schedule, allow_large)


def saved(folder: Path) -> Sweep:
    """The sweep a folder holds, as its sweep.json records it."""
    return rundir.args_from_saved(Sweep, rundir.read_json(Path(folder) / rundir.SWEEP_FILE), out=Path(folder))


# A sweep's report, rewritten whenever it finishes (`run`); an extension keeps the earlier one.
REPORT_FILES = ("table1.md", "table1.csv", rundir.PER_SEED_FILE, "learning_curves.png")


def updates_of(spec: Sweep) -> int:
    """How many updates every arm of `spec` trains (its --num-updates, else the preset's):
    one number, or a one-line error where its arms set different ones."""
    counts = {method: method_schedule(method, spec)[0].num_updates for method in spec.methods}
    if len(set(counts.values())) != 1:
        raise errors.UserError(
            f"the arms of {spec.out} train different numbers of updates ({counts}); "
            "a sweep can only be extended as a whole"
        )
    return next(iter(counts.values()))


def extend(folder: Path, num_updates: int, allow_large: bool = False) -> Sweep:
    """Make the sweep in `folder` (finished or not) one of `num_updates` updates, to be
    continued by `run(..., resume=True)`: every arm then trains on from where it stopped,
    from its checkpoint, to `num_updates`, chooses each seed's model again over all its
    validations, and is tested again. Nothing in training depends on the total, so where
    the sweep's updates are a whole number of chunks (else it says so) the result is that
    of the sweep that had asked for `num_updates` from the start, bit for bit on the same
    platform. The earlier results stay: the sweep's report moves into
    `report_<n>_updates/` and each finished arm's results.json becomes
    `results_<n>_updates.json` beside it (n the updates it had; the models they describe
    are not kept, the checkpoints move on), and sweep.json records each extension
    ("extensions"). Refused in one line, before anything moves: fewer updates than the
    sweep has, a sweep that could not be resumed (`check`, `check_started`), or an arm that
    cannot continue (`check_continuable`). A kill part-way is repaired by the same call
    again. Returns the extended sweep."""
    folder = Path(folder)
    rundir.prepare_run_dir(folder, resume=True, overwrite=False, marker=rundir.SWEEP_FILE, kind="sweep")
    spec = saved(folder)
    had = updates_of(spec)
    if num_updates < had:
        raise errors.UserError(
            f"--num-updates {num_updates} would shorten {folder} ({had} updates); a sweep can only "
            "be extended (or trained anew in another --out)"
        )
    if num_updates == had:
        return spec
    # The methods --reuse gave the sweep are in it now; its sources, of `had` updates, no
    # longer share its protocol, so the extended sweep names none ("extensions" keeps them).
    extended = dataclasses.replace(spec, num_updates=num_updates, reuse=())
    check(extended, allow_large)
    check_started(extended)
    for method in spec.methods:
        check_continuable(rundir.arm_folder(folder, method))
    kept = folder / rundir.kept_report(had)
    report_files = [folder / name for name in REPORT_FILES if (folder / name).is_file()]
    taken = [path.name for path in report_files if (kept / path.name).exists()]
    if taken:
        raise errors.UserError(f"{folder} already holds {', '.join(taken)} in {kept.name}/; move them first")
    chunks = {method_schedule(m, spec)[1].chunk_updates for m in spec.methods}
    if any(had % chunk for chunk in chunks):
        print(
            f"warning: {folder} has {had} updates, not a whole number of chunks ({sorted(chunks)}): extended, it "
            f"validates at {had}, where a sweep of {num_updates} from the start does not, so it will not end as "
            "one",
            file=sys.stderr,
            flush=True,
        )
    for path in report_files:  # before sweep.json: a kill in between leaves an extension to repeat
        kept.mkdir(exist_ok=True)
        path.rename(kept / path.name)
    record = rundir.read_json(folder / rundir.SWEEP_FILE)
    extensions = [
        *record.get("extensions", []),
        {"from_updates": had, "to_updates": num_updates, "reuse": [str(p) for p in spec.reuse]},
    ]
    rundir.write_json(folder / rundir.SWEEP_FILE, {**dataclasses.asdict(extended), "extensions": extensions})
    print(
        f"extending {folder} from {had} to {num_updates} updates"
        + (f" (its {had}-update report is kept in {kept.name}/)" if report_files else ""),
        flush=True,
    )
    for method in spec.methods:  # no finished arm reads as one of `num_updates` (a kill before: `run_method`)
        finished = rundir.read_results(rundir.arm_folder(folder, method))
        if finished is not None:
            set_aside(rundir.arm_folder(folder, method), finished["updates"])
    return extended


def _differences(a: Sweep, b: Sweep) -> list[str]:
    return [
        f.name
        for f in dataclasses.fields(Sweep)
        if f.name != "out" and rundir.jsonable(getattr(a, f.name)) != rundir.jsonable(getattr(b, f.name))
    ]


def run(
    spec: Sweep,
    *,
    resume: bool = False,
    overwrite: bool = False,
    stop_after_chunks: Optional[int] = None,
    progress: bool = True,
    allow_large: bool = False,
) -> list[dict] | None:
    """Train every arm of `spec` over its seeds (arms other sweeps finished are taken
    from `spec.reuse`), then write the report into `spec.out`: Table 1's layout of the
    selected models (Markdown and CSV), the arms paired with the first, the selected and
    last models per seed, every seed's results (results_per_seed.json) and the learning
    curves (PNG). Returns Table 1's rows, or None when `stop_after_chunks` (chunks of this
    call) ran out first.

    `resume` continues the sweep in `spec.out`, which must have been started as `spec`
    (`saved`); without it `spec.out` must be new or empty, or a sweep folder (sweep.json)
    to replace with `overwrite` (`rundir.prepare_run_dir`); `allow_large` runs past
    `presets.check_sizes`'s bounds."""
    flags.check_stop_after_chunks(stop_after_chunks, least=0)
    check(spec, allow_large)
    sources = reuse_sources(spec)
    out = spec.out
    if resume:
        rundir.prepare_run_dir(out, resume=True, overwrite=overwrite, marker=rundir.SWEEP_FILE, kind="sweep")
        differ = _differences(saved(out), spec)
        if differ:
            raise errors.UserError(
                f"{out} was started as another sweep (its {', '.join(differ)} differ); continue it "
                "with the arguments in its sweep.json (`experiments.sweep --resume --out` reads "
                "them), or write this one to another folder"
            )
        check_started(spec)
    else:
        rundir.prepare_run_dir(out, resume=False, overwrite=overwrite, marker=rundir.SWEEP_FILE, kind="sweep")
        rundir.write_started_args(out / rundir.SWEEP_FILE, spec, ())
    copy_finished(spec, sources)

    used = devices.seed_mesh(spec.seeds).devices.size
    print(
        f"{len(spec.methods)} method(s) x {spec.seeds} seed(s), the seeds spread over {used} of the "
        f"{jax.device_count()} local device(s)",
        flush=True,
    )
    config, _ = method_schedule(spec.methods[0], spec)
    evaluator = Evaluator.for_config(config)  # one for the sweep: each method's evaluation compiles once
    bar = progress_bar(config.num_updates * len(spec.methods), 0, progress)
    t0 = time.time()
    results, curves, budget = {}, {}, [stop_after_chunks]
    with loop.interruptible() as stop:  # a first Ctrl-C stops after the current chunk
        for method in spec.methods:
            ran = run_method(method, spec, bar, evaluator, rundir.arm_folder(out, method), budget)
            if ran is None:
                bar(0, None)
                if stop.requested:
                    done = (rundir.read_progress(rundir.arm_folder(out, method)) or {"done": 0})["done"]
                    print(f"interrupted at update {done} of {method}; continue with --resume", flush=True)
                else:
                    print(f"stopped after {stop_after_chunks} chunks, in {method} (continue with --resume)")
                return None
            results[method], x, y = ran
            curves[method] = (x, figures.smooth(y))
    bar(0, None)
    md, rows = report(spec, results)
    (out / "table1.md").write_text(md)
    rundir.write_csv(out / "table1.csv", rows)
    rundir.write_json(out / rundir.PER_SEED_FILE, results)
    figures.learning_curve_png(out / "learning_curves.png", curves)
    print(md)
    print(f"wrote {out}/table1.md, table1.csv, results_per_seed.json, learning_curves.png ({time.time() - t0:.0f} s)")
    return rows


def report(spec: Sweep, results: dict[str, list[dict]]) -> tuple[str, list[dict]]:
    """(the sweep's Markdown report, Table 1's rows) from its arms' per-seed results."""
    selected = {method: [r["selected"] for r in per_seed] for method, per_seed in results.items()}
    rows = table(selected)
    title = (
        f"Table 1 layout: test split, preset {spec.preset}, seeds {spec.seed}-{spec.seed + spec.seeds - 1} "
        "(each seed's model selected on validation)"
    )
    md = table_markdown(rows, title) + "\n" + selection_markdown(results)
    if len(selected) > 1 and spec.seeds > 1:
        md += "\n" + paired_markdown(selected)
    md += "\n" + by_length_markdown(results)
    md += "\n" + diagnostics_markdown(results)
    md += "\n" + numerics.markdown(results, [(spec.methods[0], m) for m in spec.methods[1:]])
    md += assembled_markdown({method: rundir.arm_folder(spec.out, method) for method in spec.methods})
    return md, rows
