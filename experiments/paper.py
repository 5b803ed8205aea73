"""The paper's evaluation from one command:
`python -m experiments.paper --preset quick --seeds 5 --out runs/paper`.

It runs one seed sweep per setup (`experiments.sweep`, the protocol of `train`: each
seed's model selected on validation) over the methods of the paper's tables, then writes
`report.md` with a CSV beside each table and a PNG beside each figure:

- Table 1: both setups (savn: A3C, A3C+MAML, A3C+ForeSIT, A3C+MAML+ForeSIT; org: A3C+ORG,
  A3C+ORG+ForeSIT), SPL, SR, SPL>=5, SR>=5 over seeds, beside the paper's numbers;
- Table 2: SPL/SR per room type of the +ForeSIT pairs;
- Table 3: the ablations RND, INT, ATT and ForeSIT on the ORG base;
- the attention critic alone (A3C+critic, A3C+ORG+critic: not rows of the paper), which
  separates what the critic does from what the imagination adds, in the claims below;
- the model selected on validation against the last one;
- SR and SPL by optimal path length (buckets of L^g) with 95% bands over seeds, and the
  paired difference per bucket, for each +ForeSIT pair;
- the paper's claims, each with a verdict ("holds", "does not hold", "cannot tell at this
  budget": a paired t interval over seeds, `experiments.reporting.stats`) and its numbers;
- ORG's rows (greedy at evaluation, as ORG's code) with sampled actions too, on the same test
  episodes, paired: greedy play can loop where sampling escapes;
- the imagination probes (`experiments.probe`) of A3C+ForeSIT and A3C+ORG+ForeSIT, every seed:
  test SR with i_tau trained, noise-free, from an untrained f_w and shuffled; f_w's fit
  against the target category's mean; where the sub-goal falls in its episode;
- the C-VAE comparison (`experiments.cvae_compare`) on the first seed of a ForeSIT method;
- Figure 3: trajectories of the baseline and of ForeSIT on the same test episodes;
- Figure 4: t-SNE of imagined states f_w([s_0 : g_tau]) and of the selected sub-goals;
- learning curves of every method with bands over seeds (one PNG per setup).

`--exclude` leaves methods out (the report says which, and the claims that need them read
"not run"); on a CPU the MAML rows take hours (docs/evaluation.md). A killed run resumes with
`--resume`: finished sweeps and methods are kept, a started one continues from its last
checkpoint (`experiments.sweep`), and the report is written again from the results.
`--reuse RUN ...` combines runs: the methods RUN has finished (a paper run of the same
preset and overrides, e.g. the MAML rows run on another machine with `--exclude`, or a
sweep folder of `experiments.sweep`, which lends its setup's rows) are copied into --out
instead of trained, and the report covers them all. They combine seed by
seed (`experiments.running.sweeps.copy_finished`): `--seeds 5 --reuse A B` with seeds 0-1 in A and
2-4 (`--seed 2 --seeds 3`) in B trains nothing, so a 5-seed report can be made in blocks of
seeds, on several machines or one after another.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import sys
import time
from pathlib import Path

from experiments import errors
from experiments.reporting.paper_tables import (
    GROUPS,
    SETUP_OF,
)
from experiments.running import devices, flags, numerics, paper_report, presets, sweeps
from experiments import rundir
from experiments.running.presets import split_arm


@dataclasses.dataclass(frozen=True)
class Args:
    """Train the paper's methods over seeds and write its tables, figures and verdicts."""

    preset: presets.PresetFlag = "quick"
    seeds: int = 5
    """Seeds per method."""
    seed: int = 0
    """Base seed: seed i is the run `train --seed <seed + i>` would make."""
    out: Path = Path("runs/paper")
    """Output folder (report.md, one sweep folder per setup)."""
    exclude: tuple[str, ...] = ()
    """Methods to leave out (e.g. a3c+maml a3c+maml+foresit on a CPU)."""
    arms: tuple[str, ...] = ()
    """Methods of the tables run with Config fields of their own, METHOD@field=value,...:
    e.g. each method at the learning rate `experiments.tune` chose for it on validation
    (a3c@learning_rate=1e-3 a3c+foresit@learning_rate=3e-4). Rows keep the method's name;
    the report lists the arms."""
    resume: flags.Resume = False
    overwrite: flags.Overwrite = False
    reuse: flags.Reuse = ()  # a sweep folder lends the sweep of its own setup (`reuse_sweeps`)
    num_updates: flags.NumUpdates = None
    test_episodes_per_room: flags.TestEpisodes = None
    val_episodes_per_room: flags.ValEpisodes = None
    cvae_windows: int = 100
    """Windows the C-VAE comparison collects its sub-goals from."""
    cvae_epochs: int = 50
    """Epochs of the C-VAE comparison's fits."""
    trajectory_candidates: int = 32
    """Figure 3: test episodes per room type among which the first with L^g >= 5 is drawn."""
    tsne_points: int = 400
    """Figure 4: most sub-goal items embedded (each gives an imagined and a selected state)."""
    probe_episodes_per_room: int = 50
    """Test episodes per room type of each condition of the imagination probes."""
    fast_compile: bool | None = None
    """Compile with most of XLA's optimisations off (jax's `jax_disable_most_optimizations`):
    programs compile in a fraction of the time and run slower. By default on for the tiny
    preset alone, a smoke run whose time is mostly compiling; its numbers then differ from a
    normally compiled run's in the last bits, and each run records it with its platform."""
    stop_after_chunks: flags.StopAfterChunks = None
    progress: flags.Progress = True
    allow_large: flags.AllowLarge = False


def fast_compile(args: Args) -> bool:
    """Whether this report compiles with most XLA optimisations off (`Args.fast_compile`)."""
    return args.preset == "tiny" if args.fast_compile is None else args.fast_compile


def arm_of(args: Args, method: str) -> str:
    """The arm `method` runs as (`--arms`), or the method itself: its folder's name in its sweep."""
    return {split_arm(a)[0]: a for a in args.arms}.get(method, method)


def sweep_args(args: Args, setup: str, methods: tuple[str, ...]) -> sweeps.Sweep:
    """The sweep of `setup` over `methods` (each run as its arm, `arm_of`)."""
    fields = ("seeds", "preset", "seed", "num_updates", "test_episodes_per_room", "val_episodes_per_room")
    reuse = reuse_sweeps(args, setup)
    methods = tuple(arm_of(args, m) for m in methods)
    return sweeps.Sweep(
        methods=methods, setup=setup, out=args.out / setup, reuse=reuse, **{k: getattr(args, k) for k in fields}
    )


def reuse_sweeps(args: Args, setup: str) -> tuple[Path, ...]:
    """The sweep folders --reuse lends `setup`'s sweep: a paper run's sweep of `setup`, or
    a sweep folder (`experiments.sweep`) run on `setup` itself."""
    folders = []
    for run in map(Path, args.reuse):
        if rundir.is_sweep(run / setup):
            folders.append(run / setup)
        elif (
            not (run / rundir.PAPER_FILE).is_file() and rundir.read_json(run / rundir.SWEEP_FILE).get("setup") == setup
        ):
            folders.append(run)
    return tuple(folders)


def check(args: Args) -> None:
    unknown = [m for m in args.exclude if m not in SETUP_OF]
    if unknown:
        raise errors.UserError(
            f"--exclude {' '.join(unknown)}: not a method of the paper's tables; they are {', '.join(SETUP_OF)}"
        )
    if not any(m not in args.exclude for m in SETUP_OF):
        raise errors.UserError("--exclude leaves no method to run")
    armed = [split_arm(a)[0] for a in args.arms]  # split_arm's ValueError names a malformed arm
    wrong = [a for a, m in zip(args.arms, armed) if m not in SETUP_OF or m in args.exclude]
    if wrong:
        raise errors.UserError(
            f"--arms {' '.join(wrong)}: each arm's method must be a method of the paper's tables "
            "that runs (not excluded)"
        )
    if len(set(armed)) != len(armed):
        raise errors.UserError("--arms: give each method at most one arm")
    if args.seeds < 1:
        raise errors.UserError(f"--seeds must be >= 1, got {args.seeds}")
    for run in map(Path, args.reuse):
        if not (run / rundir.PAPER_FILE).is_file() and not rundir.is_sweep(run):
            raise errors.UserError(
                f"--reuse {run}: neither a paper run (no paper.json) nor a sweep folder (no sweep.json)"
            )
        if run.resolve() == Path(args.out).resolve():
            raise errors.UserError(f"--reuse {run}: the run being written (--out); to continue it use --resume")
    for setup, group in GROUPS.items():  # each setup's sweep checks its sources' protocol (and its own)
        setup_args = sweep_args(args, setup, tuple(m for m in group if m not in args.exclude))
        if setup_args.methods:  # the seeds and sizes of its arms, before anything is written
            sweeps.check(setup_args, args.allow_large)
        sweeps.reuse_sources(setup_args)
        if args.resume and rundir.is_sweep(setup_args.out):
            sweeps.check_started(setup_args)
    for name in ("cvae_windows", "cvae_epochs", "trajectory_candidates", "tsne_points", "probe_episodes_per_room"):
        if getattr(args, name) < 1:
            raise errors.UserError(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")


def main(args: Args) -> dict | None:
    """Run (or continue) every sweep, then write the report; returns the claims
    ({claim: verdict line}), or None when stopped by --stop-after-chunks."""
    flags.check_stop_after_chunks(args.stop_after_chunks, least=0)
    if args.resume:
        args = rundir.resumed_args(args, rundir.PAPER_FILE, "paper run", keep=flags.INVOCATION)
    check(args)
    if importlib.util.find_spec("sklearn") is None:  # Figure 4's t-SNE, drawn after the training
        raise errors.UserError(
            "the paper report needs scikit-learn (Figure 4's t-SNE): pip install 'foresit_jax[paper]'"
        )
    for method in SETUP_OF:  # fail before any training
        sweeps.method_schedule(arm_of(args, method), sweeps.Sweep(preset=args.preset, setup=SETUP_OF[method]))
    if not args.resume:
        rundir.prepare_run_dir(
            args.out, resume=False, overwrite=args.overwrite, marker=rundir.PAPER_FILE, kind="paper run"
        )
        rundir.write_started_args(args.out / rundir.PAPER_FILE, args, flags.INVOCATION)
    with numerics.compiled_fast(fast_compile(args)):
        return _run(args)


def _run(args: Args) -> dict | None:
    """`main` after its checks: the sweeps, then the report."""
    t0, run = time.time(), paper_run(args)
    results = {}
    for setup, group in GROUPS.items():
        methods = tuple(m for m in group if m not in args.exclude)
        if not methods:
            continue
        print(f"== {setup} setup: {', '.join(methods)}", flush=True)
        spec = sweep_args(args, setup, methods)
        ran = sweeps.run(
            spec,
            resume=rundir.is_sweep(spec.out),
            stop_after_chunks=args.stop_after_chunks,
            progress=args.progress,
            allow_large=args.allow_large,
        )
        if ran is None:
            print("stopped (continue with --resume)")
            return None
        per_seed = rundir.read_json(args.out / setup / rundir.PER_SEED_FILE)
        results.update(run.by_method(per_seed))
    print(f"sweeps done ({time.time() - t0:.0f} s); writing the report", flush=True)
    return paper_report.write(run, results)


def paper_run(args: Args) -> paper_report.PaperRun:
    """What the report needs of this paper run (`paper_report.PaperRun`)."""
    return paper_report.PaperRun(
        out=args.out,
        preset=args.preset,
        seed=args.seed,
        seeds=args.seeds,
        arms={split_arm(a)[0]: a for a in args.arms},
        specs={
            setup: sweep_args(args, setup, tuple(m for m in group if m not in args.exclude))
            for setup, group in GROUPS.items()
        },
        cvae_windows=args.cvae_windows,
        cvae_epochs=args.cvae_epochs,
        trajectory_candidates=args.trajectory_candidates,
        tsne_points=args.tsne_points,
        probe_episodes_per_room=args.probe_episodes_per_room,
    )


def cli(argv=None) -> dict | None:
    return errors.run_cli(Args, main, argv)


def console() -> None:
    """The `foresit-paper` console script: as `python -m experiments.paper`."""
    devices.split_host_into_devices()  # before jax starts: faster on a CPU (see experiments.running.devices)
    cli(sys.argv[1:])


if __name__ == "__main__":
    console()
