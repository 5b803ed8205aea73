"""Tuning as part of a comparison: `python -m experiments.tune --methods a3c a3c+critic a3c+foresit
--grid learning_rate=3e-4,1e-3 --seeds 5 --preset quick --out runs/tune`.

Every method is trained at every value of the grid over the same seeds: each (method,
value) is an arm `METHOD@field=value` of one seed sweep (`experiments.sweep`, in
`--out/sweep`, a sweep folder that `compare`, `evaluate` and `probe` read as any other).
Each method's value is then chosen by its mean validation SR over the seeds (each seed's
selected model's validation SR, `experiments.reporting.tuning.choose`): the test split never chooses. The report
(`tune.md`, `tune.json`, `tune_curves.png` in --out) has:

* the grid: per method and value, the validation SR that chose, the test SR and SPL, the
  chosen value marked;
* best vs best, the fair comparison: every pair of methods, each at its own chosen value,
  paired seed by seed (`experiments.reporting.report.paired_report`: difference and t interval,
  IQM, P(B > A), Holm over these pairs, the minimum detectable effect);
* the same pairs at each common value of the grid (one family per value);
* the learning curves of every value, one panel per method;
* the `experiments.paper` command that reports the paper's tables with each method at its
  chosen value (`--arms`), reusing the arms trained here.

Several `--grid` fields make their product (`--grid learning_rate=3e-4,1e-3
entropy_coef=0.01,0.02`). `--resume` continues a killed tune; `--reuse` takes arms that
other sweeps or tunes of the same protocol finished (`experiments.running.sweeps.copy_finished`), an
arm at the preset's own value also from a sweep that ran it under its plain method name
(`a3c` at quick is `a3c@learning_rate=1e-3`). The grid runs arm after arm, each arm's seeds
vmapped in one program, so seed s at value v is the seed s of a sweep of that arm. (A grid
of learning rates in one program, for an accelerator: `foresit_jax.train.GridTrainer`,
docs/reproducibility.md.)
"""

from __future__ import annotations

import dataclasses
import itertools
import sys
from pathlib import Path

from experiments import errors
from experiments.reporting import tuning
from experiments.running import devices, flags, presets, sweeps
from experiments import rundir
from experiments.running.presets import SweepConfigFields, config_flag, duplicate_arms, normalise_arm, split_arm


@dataclasses.dataclass(frozen=True)
class Args:
    """Train every method at every grid value over the same seeds, choose each method's value on validation, pair them."""

    methods: presets.MethodsFlag = ("a3c", "a3c+critic", "a3c+foresit")
    grid: tuple[str, ...] = ("learning_rate=3e-4,1e-3",)
    """FIELD=V1,V2,...: a Config field and its values; several fields make their product."""
    setup: presets.SetupFlag = "savn"
    seeds: int = 5
    """Seeds per arm (vmapped in one program)."""
    preset: presets.PresetFlag = "quick"
    seed: int = 0
    """Base seed: seed i is the run `train --seed <seed + i>` would make."""
    out: Path = Path("runs/tune")
    """Output folder (the sweep of the arms goes to its sweep/)."""
    resume: flags.Resume = False
    overwrite: flags.Overwrite = False
    reuse: flags.Reuse = ()
    num_updates: flags.NumUpdates = None
    test_episodes_per_room: flags.TestEpisodes = None
    val_episodes_per_room: flags.ValEpisodes = None
    stop_after_chunks: flags.StopAfterChunks = None
    progress: flags.Progress = True
    allow_large: flags.AllowLarge = False
    config: config_flag(SweepConfigFields) = dataclasses.field(default_factory=SweepConfigFields)
    """Every other Config field for every arm, e.g. --priors True --perception-range 4: the preset's (or the
    arm's) unless given; a field --grid varies is refused here."""


def parse_grid(specs) -> list[tuple[str, list[str]]]:
    """`--grid`'s FIELD=V1,V2,... items -> [(field, [value text, ...])]; one-line errors
    for what does not parse (whether a field may be set and a value has its type is checked
    on the arms, `arms`)."""
    if not specs:
        raise errors.UserError("--grid needs at least one FIELD=V1,V2,... (e.g. learning_rate=3e-4,1e-3)")
    grid = []
    for spec in specs:
        field, eq, body = (x.strip() for x in spec.partition("="))
        values = [v.strip() for v in body.split(",") if v.strip()]
        if not eq or not field or not values:
            raise errors.UserError(f"--grid {spec!r}: write FIELD=V1,V2,... (e.g. learning_rate=3e-4,1e-3)")
        if len(set(values)) != len(values):
            raise errors.UserError(f"--grid {spec!r}: a value is given twice")
        if field in dict(grid):
            raise errors.UserError(f"--grid: {field} is given twice; give its values in one FIELD=V1,V2,...")
        grid.append((field, values))
    return grid


def points(grid) -> list[str]:
    """The grid's points, in order (the last field varying fastest): 'field=v,...' each."""
    return [
        ",".join(f"{f}={v}" for f, v in zip(dict(grid), combo)) for combo in itertools.product(*dict(grid).values())
    ]


def arm(method: str, point: str) -> str:
    """The arm of `method` at a grid point: `a3c` at 'learning_rate=3e-4' is
    `a3c@learning_rate=3e-4`; an arm's own fields stay (`a3c@x=1` -> `a3c@x=1,learning_rate=3e-4`)."""
    return method + ("," if "@" in method else "@") + point


def arms(args: Args, grid) -> dict[str, dict[str, str]]:
    """{method: {point: arm}}, every arm checked against the preset: a field an arm cannot
    set, a value not of its type, or a grid field the method's own arm fields set is refused."""
    table = {}
    for method in args.methods:
        _, own = split_arm(method)
        clash = sorted(set(own) & set(dict(grid)))
        if clash:
            raise errors.UserError(
                f"--methods {method}: sets {', '.join(clash)}, which --grid varies; drop it from one"
            )
        table[method] = {p: arm(method, p) for p in points(grid)}
        configs = {}
        for point, name in table[method].items():  # a ValueError names what is wrong
            config, _ = sweeps.method_schedule(name, sweep_args(args, (name,), Path(".")))
            same = [p for p, c in configs.items() if c == config]
            if same:
                raise errors.UserError(
                    f"--grid: {method} at {point} trains what it trains at {same[0]}; give distinct values"
                )
            configs[point] = config
    return table


def sweep_args(args: Args, methods: tuple[str, ...], folder: Path) -> sweeps.Sweep:
    """The sweep of `methods` (arms) in `folder` under the tune's protocol."""
    reuse = tuple(f / "sweep" if (Path(f) / rundir.TUNE_FILE).is_file() else Path(f) for f in map(Path, args.reuse))
    return sweeps.Sweep(
        methods=methods,
        setup=args.setup,
        seeds=args.seeds,
        preset=args.preset,
        seed=args.seed,
        out=folder,
        reuse=reuse,
        num_updates=args.num_updates,
        test_episodes_per_room=args.test_episodes_per_room,
        val_episodes_per_room=args.val_episodes_per_room,
        config=args.config,
    )


def tune_report(args: Args, grid, table: dict, results: dict) -> tuple[str, dict]:
    """tune.md's text and tune.json's numbers (`experiments.reporting.tuning.tune_report`)."""
    return tuning.tune_report(
        args.methods, [f for f, _ in grid], points(grid), args.preset, args.setup, args.out / "sweep", table, results
    )


def main(args: Args) -> dict | None:
    """Run (or continue) the tune; returns tune.json's numbers (None when stopped early)."""
    flags.check_stop_after_chunks(args.stop_after_chunks, least=0)
    if args.resume:
        args = rundir.resumed_args(args, rundir.TUNE_FILE, "tune", keep=flags.INVOCATION)
    if args.seeds < 1:
        raise errors.UserError(f"--seeds must be >= 1, got {args.seeds}")
    if not args.methods:
        raise errors.UserError("--methods needs at least one method, each once")
    for first, again in duplicate_arms(args.methods):  # the same arm however it is spelt (`normalise_arm`)
        same = "more than once" if first == again else f"and {again}, the same arm ({normalise_arm(first)})"
        raise errors.UserError(f"--methods lists {first} {same}; give each method once")
    grid = parse_grid(args.grid)
    table = arms(args, grid)
    names = tuple(a for by_point in table.values() for a in by_point.values())
    folder = args.out / "sweep"
    sweeps.check(sweep_args(args, names, folder), args.allow_large)  # the seeds and sizes, before writing
    if not args.resume:
        rundir.prepare_run_dir(args.out, resume=False, overwrite=args.overwrite, marker=rundir.TUNE_FILE, kind="tune")
        rundir.write_started_args(args.out / rundir.TUNE_FILE, args, flags.INVOCATION)
    print(
        f"tuning {', '.join(f for f, _ in grid)}: {len(args.methods)} method(s) x {len(points(grid))} value(s) "
        f"= {len(names)} arms, {args.seeds} seed(s) each",
        flush=True,
    )
    ran = sweeps.run(
        sweep_args(args, names, folder),
        resume=rundir.is_sweep(folder),
        stop_after_chunks=args.stop_after_chunks,
        progress=args.progress,
        allow_large=args.allow_large,
    )
    if ran is None:
        print("continue with: python -m experiments.tune --resume --out " + str(args.out))
        return None
    results = {
        a: rundir.read_results(rundir.arm_folder(args.out / "sweep", a), required=True)["results"] for a in names
    }
    md, out = tune_report(args, grid, table, results)
    (args.out / "tune.md").write_text(md)
    rundir.write_json(args.out / "tune_results.json", out)
    tuning.curves_png(args.out / "tune_curves.png", table, results)
    print(md)
    print(f"wrote {args.out}/tune.md, tune_results.json, tune_curves.png")
    return out


def cli(argv=None) -> dict | None:
    return errors.run_cli(Args, main, argv)


def console() -> None:
    """The `foresit-tune` console script: as `python -m experiments.tune`."""
    devices.split_host_into_devices()  # before jax starts (see experiments.running.devices)
    cli(sys.argv[1:])


if __name__ == "__main__":
    console()
