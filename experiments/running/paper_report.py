"""The paper report (report.md) from a paper run's folder: each section from the setups'
sweep folders, through the reporting layer's tables (`experiments.reporting.paper_tables`)
and the figures and rows that read trained models back (`paper_figures`). The CLI
(`experiments.paper`) runs the sweeps and hands this module a `PaperRun`."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from experiments import rundir
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
from experiments.running import devices, numerics, paper_figures, probe_runs, sweeps
from experiments.running.models import models_of_sweep


@dataclasses.dataclass(frozen=True)
class PaperRun:
    """A paper run's folder `out` and what its report needs: the seeds `seed`..`seed +
    seeds - 1` of preset `preset`; `arms` {method: the arm it ran as, its folder's name in
    its setup's sweep}; `specs` {setup: the sweep it ran, which gives its methods' Config};
    and the sizes of the report's parts (the C-VAE
    comparison's windows and epochs, Figure 3's candidates, Figure 4's points, the probes'
    episodes per room type)."""

    out: Path
    preset: str
    seed: int
    seeds: int
    arms: dict[str, str]
    specs: dict[str, sweeps.Sweep]
    cvae_windows: int = 100
    cvae_epochs: int = 50
    trajectory_candidates: int = 32
    tsne_points: int = 400
    probe_episodes_per_room: int = 50

    def arm(self, method: str) -> str:
        return self.arms.get(method, method)

    def by_method(self, by_arm: dict) -> dict:
        """`by_arm` (keyed by the arms' folder names) keyed by their methods."""
        names = {self.arm(m): m for m in SETUP_OF}
        return {names.get(name, name): value for name, value in by_arm.items()}

    def folder(self, method: str) -> Path:
        """The run folder of `method`'s arm in its setup's sweep."""
        return rundir.arm_folder(self.out / SETUP_OF[method], self.arm(method))


def write(run: PaperRun, results: dict) -> dict:
    """report.md (and a CSV beside each table, a PNG beside each figure) from `results`
    ({method: per-seed results}); prints it and returns the claims ({claim: verdict line})."""
    out = run.out
    seeds = f"{run.seed}-{run.seed + run.seeds - 1}" if run.seeds > 1 else str(run.seed)
    excluded = [m for m in SETUP_OF if m not in results]
    md = [
        f"# ForeSIT on GridNav: the paper's evaluation (preset {run.preset}, seeds {seeds})\n",
        f"Test split, each seed's model selected on validation (`experiments.running.selection`); mean ± sample std "
        f"[95% Student-t interval] over {run.seeds} seed(s). Not run: {', '.join(excluded) or 'none'}.\n",
    ]
    if run.arms:
        md.append(
            "Methods run with fields of their own (`--arms`; the rows keep the method's name): "
            + "; ".join(f"{method} at {arm.partition('@')[2]}" for method, arm in run.arms.items())
            + ".\n"
        )
    compared = [*PAIRS, *(("a3c+org+foresit", m) for m in TABLE3[1:-1])]  # the claims' pairs
    md.append(numerics.markdown(results, compared) + sweeps.assembled_markdown({m: run.folder(m) for m in results}))
    for title, (text, rows), name in (
        ("Table 1", table1(results), "table1"),
        ("Table 2: SPL / SR per room type", table2(results), "table2"),
        ("Table 3: what to imagine (ablations on the ORG base)", table3(results), "table3"),
    ):
        rundir.write_csv(out / f"{name}.csv", rows)
        md.append(f"## {title}\n\n" + text)
    md.append(report.selection_markdown(results))
    md.append("## SR and SPL by optimal path length\n\n" + by_length_section(run, results))
    lines = claims(results)
    rundir.write_csv(out / "claims.csv", [{"claim": c, "verdict": v, "numbers": n} for c, v, n in lines])
    md.append("## The paper's claims\n\n" + claims_markdown(lines))
    md.append(sampled_section(run, results))
    md.append(probe_section(run, results))
    md.append(foresit_sections(run, results))
    md.append(trajectories_section(run, results))
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


def by_length_section(run: PaperRun, results: dict) -> str:
    """For each +ForeSIT pair: a PNG of SR and SPL by L^g bucket with 95% bands over seeds,
    and the paired difference per bucket."""
    rows = by_length_rows(results)
    rundir.write_csv(run.out / "by_length.csv", rows)
    md = ""
    for base, other in PAIRS:
        if base not in results or other not in results:
            continue
        name = f"by_length_{base}_vs_{other}.png".replace("+", "_")
        by_length_png(run.out / name, [r for r in rows if r["method"] in (base, other)])
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


def first_seed(run: PaperRun, method: str):
    """(config, trainer, last training state, selected AgentParams) of `method`'s first seed."""
    config, trainer, states, best = sweeps.load_method(run.arm(method), run.specs[SETUP_OF[method]], run.folder(method))
    return config, trainer, devices.seed_slice(states, 0), devices.seed_slice(best, 0)


def sampled_section(run: PaperRun, results: dict) -> str:
    """ORG's rows (evaluated greedily, as ORG's code does) evaluated with sampled actions
    too, on the same test episodes (also written to sampled.csv)."""
    greedy = [m for m in results if sweeps.method_schedule(m, run.specs[SETUP_OF[m]])[0].pieces.greedy_evaluation]
    title = "## ORG's rows with sampled actions\n\n"
    if not greedy:
        return title + "Not run: no method evaluated greedily (ORG's rows) was trained.\n"
    print(f"sampled actions: {', '.join(greedy)}", flush=True)
    sampled = {}
    for setup in dict.fromkeys(SETUP_OF[m] for m in greedy):
        arms = [run.arm(m) for m in greedy if SETUP_OF[m] == setup]
        sampled.update(run.by_method(paper_figures.sampled_results(run.out / setup, arms)))
    md, rows = sampled_markdown(results, sampled)
    rundir.write_csv(run.out / "sampled.csv", rows)
    return (
        title + "ORG's code acts greedily at evaluation (the argmax of the policy), SAVN's samples; greedy play can "
        "loop where sampling escapes. Each seed's selected model on the same test episodes with each rule; mean "
        "± sample std over seeds, the difference paired over seeds.\n\n" + md
    )


def probe_section(run: PaperRun, results: dict) -> str:
    """The imagination probes (`experiments.probe`) of the +ForeSIT methods of `PROBED`
    that ran, every seed, as a report section (also written to probe.json)."""
    methods = [m for m in PROBED if m in results]
    if not methods:
        return "## Imagination probes\n\nNot run: no probed ForeSIT method was trained.\n"
    models = {}
    for m in methods:
        models.update(run.by_method(models_of_sweep(run.out / SETUP_OF[m], (run.arm(m),))))
    found = probe_runs.probe(models, run.probe_episodes_per_room, run.cvae_windows)
    rundir.write_json(run.out / "probe.json", found)
    return probing.markdown(found, run.probe_episodes_per_room, run.cvae_windows, level=2)


def foresit_sections(run: PaperRun, results: dict) -> str:
    """The C-VAE comparison and Figure 4 (t-SNE) on the first seed of the first ForeSIT
    method that ran (also written to cvae_comparison.json and fig4_tsne.png)."""
    foresit = next((m for m in ("a3c+foresit", "a3c+org+foresit", "a3c+maml+foresit") if m in results), None)
    if foresit is None:
        return "## C-VAE comparison, Figures 3 and 4\n\nNot run: no ForeSIT method was trained.\n"
    print(f"the C-VAE comparison on {foresit}", flush=True)
    config, trainer, state, _ = first_seed(run, foresit)
    items = cvae_comparison.collect_items(trainer, state, run.cvae_windows, run.seed)
    result = cvae_comparison.compare(config, items, run.cvae_epochs, run.seed)
    rundir.write_json(run.out / "cvae_comparison.json", result)
    compared = (
        cvae_comparison.markdown(result, config, run.cvae_windows, level=3)
        if "direct" in result
        else f"Not run: {result['items']} successful episodes in {run.cvae_windows} windows.\n"
    )
    print("Figure 4: t-SNE", flush=True)
    n = paper_figures.tsne_figure(config, trainer, state, items, run.out / "fig4_tsne.png", run.tsne_points, run.seed)
    return (
        f"## The C-VAE comparison ({foresit}, seed {run.seed})\n\n{compared}\n"
        f"## Figure 4: t-SNE of imagined states and selected sub-goals ({foresit}, seed {run.seed})\n\n"
        + (f"![t-SNE](fig4_tsne.png)\n\n{n} items.\n" if n >= 5 else f"Not drawn: {n} items.\n")
    )


def trajectories_section(run: PaperRun, results: dict) -> str:
    """Figure 3: for each pair that ran, both methods' first seeds on the same test episodes."""
    md = ["## Figure 3: trajectories on the same test episodes\n"]
    for base, other in PAIRS:
        if base in results and other in results:
            name = f"fig3_{base}_vs_{other}.png".replace("+", "_")
            print(f"Figure 3: {base} and {other}", flush=True)
            loaded = {m: first_seed(run, m)[::3] for m in (base, other)}  # (config, selected params)
            summary = paper_figures.trajectories_figure(loaded, run.seed, run.trajectory_candidates, run.out / name)
            md.append(
                f"![{base} and {other}]({name})\n\n{base} left, {other} right (seed {run.seed}; the arrow is the "
                f"start pose, the target framed in red). {summary}.\n\n"
            )
    return "\n".join(md)
