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
"not run"); on a CPU the MAML rows take hours (docs/results.md). A killed run resumes with
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
from experiments.reporting import cvae_comparison, probing, report, stats
from experiments.reporting.paper_tables import (
    GROUPS,
    PAIRS,
    PROBED,
    SETUP_OF,
    TABLE3,
    by_length_png,
    by_length_rows,
    claims,
    claims_markdown,
    fmt_pair,
    sampled_markdown,
    table1,
    table2,
    table3,
)
from experiments.reporting.tables import markdown_table
from experiments.running import devices, flags, numerics, paper_figures, probe_runs, sweeps
from experiments import rundir
from experiments.running.models import models_of_sweep
from experiments.running.presets import split_arm


@dataclasses.dataclass(frozen=True)
class Args:
    """Train the paper's methods over seeds and write its tables, figures and verdicts."""

    preset: str = "quick"
    """Preset: tiny, quick, house or paper."""
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


def by_method(args: Args, by_arm: dict) -> dict:
    """`by_arm` (keyed by the arms' folder names) keyed by their methods."""
    names = {arm_of(args, m): m for m in SETUP_OF}
    return {names.get(name, name): value for name, value in by_arm.items()}


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
        elif not (run / "paper.json").is_file() and rundir.read_json(run / rundir.SWEEP_FILE).get("setup") == setup:
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
        if not (run / "paper.json").is_file() and not rundir.is_sweep(run):
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
    if args.resume:
        args = rundir.resumed_args(args, "paper.json", "paper run", keep=flags.INVOCATION)
    check(args)
    if importlib.util.find_spec("sklearn") is None:  # Figure 4's t-SNE, drawn after the training
        raise errors.UserError(
            "the paper report needs scikit-learn (Figure 4's t-SNE): pip install 'foresit_jax[paper]'"
        )
    for method in SETUP_OF:  # fail before any training
        sweeps.method_schedule(arm_of(args, method), sweeps.Sweep(preset=args.preset, setup=SETUP_OF[method]))
    if not args.resume:
        rundir.prepare_run_dir(args.out, resume=False, overwrite=args.overwrite, marker="paper.json", kind="paper run")
        rundir.write_started_args(args.out / "paper.json", args, flags.INVOCATION)
    with numerics.compiled_fast(fast_compile(args)):
        return _run(args)


def _run(args: Args) -> dict | None:
    """`main` after its checks: the sweeps, then the report."""
    t0 = time.time()
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
        results.update(by_method(args, per_seed))
    print(f"sweeps done ({time.time() - t0:.0f} s); writing the report", flush=True)
    return write_report(args, results)


# ---------------------------------------------------------------------- the report: L^g buckets
def by_length_section(args: Args, results: dict) -> str:
    """For each +ForeSIT pair: a PNG of SR and SPL by L^g bucket with 95% bands over seeds,
    and the paired difference per bucket."""
    rows = by_length_rows(results)
    rundir.write_csv(args.out / "by_length.csv", rows)
    md = ""
    for base, other in PAIRS:
        if base not in results or other not in results:
            continue
        name = f"by_length_{base}_vs_{other}.png".replace("+", "_")
        by_length_png(args.out / name, [r for r in rows if r["method"] in (base, other)])
        cells = [
            [bucket, episodes, *(f"{fmt_pair(p)} ({stats.verdict(p)})" for p in pairs)]
            for bucket, episodes, *pairs in report.paired_by_length(results, base, other)
        ]
        md += (
            f"### {other} against {base}\n\n![SR and SPL by L^g]({name})\n\n"
            + markdown_table(cells, ["L^g", "episodes (all seeds)", "SR difference [95% CI], p", "SPL difference"])
            + "\n\n"
        )
    return md or "(no +ForeSIT pair was run)\n"


# ---------------------------------------------------------------------- the models of figures 3 and 4
def _first_seed(args: Args, method: str):
    """(config, trainer, last training state, selected AgentParams) of the first seed."""
    arm = arm_of(args, method)
    config, trainer, states, best = sweeps.load_method(
        arm, _method_args(args, method), rundir.arm_folder(args.out / SETUP_OF[method], arm)
    )
    return config, trainer, devices.seed_slice(states, 0), devices.seed_slice(best, 0)


def _method_args(args: Args, method: str) -> sweeps.Sweep:
    setup = SETUP_OF[method]
    return sweep_args(args, setup, tuple(m for m in GROUPS[setup] if m not in args.exclude))


def sampled_section(args: Args, results: dict) -> str:
    """ORG's rows (evaluated greedily, as ORG's code does) evaluated with sampled actions
    too, on the same test episodes (also written to sampled.csv)."""
    greedy = [
        m for m in results if sweeps.method_schedule(m, sweep_args(args, SETUP_OF[m], (m,)))[0].pieces.greedy_evaluation
    ]
    title = "## ORG's rows with sampled actions\n\n"
    if not greedy:
        return title + "Not run: no method evaluated greedily (ORG's rows) was trained.\n"
    print(f"sampled actions: {', '.join(greedy)}", flush=True)
    sampled = {}
    for setup in dict.fromkeys(SETUP_OF[m] for m in greedy):
        arms = [arm_of(args, m) for m in greedy if SETUP_OF[m] == setup]
        sampled.update(by_method(args, paper_figures.sampled_results(args.out / setup, arms)))
    md, rows = sampled_markdown(results, sampled)
    rundir.write_csv(args.out / "sampled.csv", rows)
    return (
        title + "ORG's code acts greedily at evaluation (the argmax of the policy), SAVN's samples; greedy play can "
        "loop where sampling escapes. Each seed's selected model on the same test episodes with each rule; mean "
        "± sample std over seeds, the difference paired over seeds.\n\n" + md
    )


# ---------------------------------------------------------------------- report.md
def probe_section(args: Args, results: dict) -> str:
    """The imagination probes (`experiments.probe`) of the +ForeSIT methods of `PROBED`
    that ran, every seed, as a report section (also written to probe.json)."""
    methods = [m for m in PROBED if m in results]
    if not methods:
        return "## Imagination probes\n\nNot run: no probed ForeSIT method was trained.\n"
    models = {}
    for m in methods:
        models.update(by_method(args, models_of_sweep(args.out / SETUP_OF[m], (arm_of(args, m),))))
    report = probe_runs.probe(models, args.probe_episodes_per_room, args.cvae_windows)
    rundir.write_json(args.out / "probe.json", report)
    return probing.markdown(report, args.probe_episodes_per_room, args.cvae_windows, level=2)


def write_report(args: Args, results: dict) -> dict:
    out = args.out
    seeds = f"{args.seed}-{args.seed + args.seeds - 1}" if args.seeds > 1 else str(args.seed)
    excluded = [m for m in SETUP_OF if m not in results]
    md = [
        f"# ForeSIT on GridNav: the paper's evaluation (preset {args.preset}, seeds {seeds})\n",
        f"Test split, each seed's model selected on validation (`experiments.running.selection`); mean ± sample std "
        f"[95% Student-t interval] over {args.seeds} seed(s). Not run: {', '.join(excluded) or 'none'}.\n",
    ]
    if args.arms:
        md.append(
            "Methods run with fields of their own (`--arms`; the rows keep the method's name): "
            + "; ".join(f"{split_arm(a)[0]} at {a.partition('@')[2]}" for a in args.arms)
            + ".\n"
        )

    compared = [*PAIRS, *(("a3c+org+foresit", m) for m in TABLE3[1:-1])]  # the claims' pairs
    md.append(
        numerics.markdown(results, compared)
        + sweeps.assembled_markdown({m: rundir.arm_folder(out / SETUP_OF[m], arm_of(args, m)) for m in results})
    )
    t1, rows1 = table1(results)
    rundir.write_csv(out / "table1.csv", rows1)
    md.append("## Table 1\n\n" + t1)
    t2, rows2 = table2(results)
    rundir.write_csv(out / "table2.csv", rows2)
    md.append("## Table 2: SPL / SR per room type\n\n" + t2)
    t3, rows3 = table3(results)
    rundir.write_csv(out / "table3.csv", rows3)
    md.append("## Table 3: what to imagine (ablations on the ORG base)\n\n" + t3)
    md.append(report.selection_markdown(results))
    md.append("## SR and SPL by optimal path length\n\n" + by_length_section(args, results))
    lines = claims(results)
    rundir.write_csv(out / "claims.csv", [{"claim": c, "verdict": v, "numbers": n} for c, v, n in lines])
    md.append("## The paper's claims\n\n" + claims_markdown(lines))
    md.append(sampled_section(args, results))
    md.append(probe_section(args, results))

    foresit = next((m for m in ("a3c+foresit", "a3c+org+foresit", "a3c+maml+foresit") if m in results), None)
    if foresit is None:
        md.append("## C-VAE comparison, Figures 3 and 4\n\nNot run: no ForeSIT method was trained.\n")
    else:
        print(f"the C-VAE comparison on {foresit}", flush=True)
        config, trainer, state, _ = _first_seed(args, foresit)
        items = cvae_comparison.collect_items(trainer, state, args.cvae_windows, args.seed)
        result = cvae_comparison.compare(config, items, args.cvae_epochs, args.seed)
        rundir.write_json(out / "cvae_comparison.json", result)
        md.append(
            f"## The C-VAE comparison ({foresit}, seed {args.seed})\n\n"
            + (
                cvae_comparison.markdown(result, config, args.cvae_windows, level=3)
                if "direct" in result
                else f"Not run: {result['items']} successful episodes in {args.cvae_windows} windows.\n"
            )
        )
        print("Figure 4: t-SNE", flush=True)
        n = paper_figures.tsne_figure(config, trainer, state, items, out / "fig4_tsne.png", args.tsne_points, args.seed)
        md.append(
            f"## Figure 4: t-SNE of imagined states and selected sub-goals ({foresit}, seed {args.seed})\n\n"
            + (f"![t-SNE](fig4_tsne.png)\n\n{n} items.\n" if n >= 5 else f"Not drawn: {n} items.\n")
        )
    md.append("## Figure 3: trajectories on the same test episodes\n")
    for base, other in PAIRS:
        if base in results and other in results:
            name = f"fig3_{base}_vs_{other}.png".replace("+", "_")
            print(f"Figure 3: {base} and {other}", flush=True)
            loaded = {m: _first_seed(args, m)[::3] for m in (base, other)}  # (config, selected params)
            summary = paper_figures.trajectories_figure(loaded, args.seed, args.trajectory_candidates, out / name)
            md.append(
                f"![{base} and {other}]({name})\n\n{base} left, {other} right (seed {args.seed}; the arrow is the "
                f"start pose, the target framed in red). {summary}.\n\n"
            )
    md.append(
        "## Learning curves (mean and band of one std over seeds)\n\n"
        + "".join(
            f"![{setup}]({setup}/learning_curves.png)\n\n"
            for setup in GROUPS
            if (out / setup / "learning_curves.png").exists()
        )
    )
    text = "\n".join(md)
    (out / "report.md").write_text(text)
    print(text)
    print(f"wrote {out / 'report.md'}")
    return {c: f"{v}: {n}" for c, v, n in lines}


def cli(argv=None) -> dict | None:
    return errors.run_cli(Args, main, argv)


def console() -> None:
    """The `foresit-paper` console script: as `python -m experiments.paper`."""
    devices.split_host_into_devices()  # before jax starts: faster on a CPU (see experiments.running.devices)
    cli(sys.argv[1:])


if __name__ == "__main__":
    console()
