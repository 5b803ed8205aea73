"""A tune's choice and report (experiments.tune trains the grid): each method's grid value
chosen by its seeds' mean validation SR, the grid's table, the pairs at each method's own
value and at every common one, the learning curves per value."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from experiments.reporting import figures, report
from experiments.reporting.tables import markdown_table
from experiments.errors import UserError


# ---------------------------------------------------------------------- choosing on validation
def selection_sr(per_seed: list[dict]) -> np.ndarray:
    """Per seed, the validation SR of its selected model (the validation at its selected
    update): what the value is chosen by. Test numbers are not read."""
    out = []
    for r in per_seed:
        at = [h["SR"] for h in r["validation"] if h["update"] == r["selected_update"]]
        if len(at) != 1:
            raise UserError(f"seed {r['seed']}: no single validation at its selected update {r['selected_update']}")
        out.append(report.rate(at[0]))
    return np.array(out)


def choose(by_point: dict[str, list[dict]]) -> str:
    """The grid point (of `by_point`: point -> a method's per-seed results there) whose mean
    validation SR (`selection_sr`) is highest; a tie goes to the first point in grid order."""
    means = {p: float(selection_sr(per_seed).mean()) for p, per_seed in by_point.items()}
    return max(means, key=lambda p: (means[p], -list(means).index(p)))


# ---------------------------------------------------------------------- the report
def _mean_std(x: np.ndarray) -> str:
    return f"{x.mean():.1f} ± {x.std(ddof=1):.1f}" if len(x) > 1 else f"{x.mean():.1f}"


def grid_table(table: dict, results: dict, chosen: dict) -> tuple[str, list[dict]]:
    rows, cells = [], []
    for method, by_point in table.items():
        for point, name in by_point.items():
            per_seed = results[name]
            val, sr, spl = selection_sr(per_seed), report.values(per_seed, "SR"), report.values(per_seed, "SPL")
            rows.append(
                {
                    "method": method,
                    "point": point,
                    "arm": name,
                    "val_SR": val.tolist(),
                    "SR": sr.tolist(),
                    "SPL": spl.tolist(),
                    "chosen": point == chosen[method],
                }
            )
            cells.append(
                [
                    method,
                    point,
                    _mean_std(val),
                    _mean_std(sr),
                    _mean_std(spl),
                    "**chosen**" if point == chosen[method] else "",
                ]
            )
    md = markdown_table(cells, ["method", "value", "validation SR (chooses)", "test SR", "test SPL", ""])
    return md + "\n", rows


def pairs_of(methods) -> list[tuple[str, str]]:
    """Every pair of methods (A before B in --methods): B - A."""
    return list(itertools.combinations(methods, 2))


def curves_png(path: Path, table: dict, results: dict) -> None:
    """One panel per method: each grid point's training success rate (smoothed, mean and
    band over seeds) and its mean validation SR (markers)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4.2 * len(table), 3.6))
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, len(table), sharey=True, squeeze=False)[0]
    for ax, (method, by_point) in zip(axes, table.items()):
        for i, (point, name) in enumerate(by_point.items()):
            per_seed, color = results[name], f"C{i}"
            y = 100 * np.array([figures.smooth(r["training_success_rate"]) for r in per_seed])
            x = np.arange(1, y.shape[1] + 1)
            ax.plot(x, y.mean(0), color=color, label=point)
            ax.fill_between(x, y.mean(0) - y.std(0), y.mean(0) + y.std(0), color=color, alpha=0.2)
            updates = [h["update"] for h in per_seed[0]["validation"]]
            val = np.array([[report.rate(h["SR"]) for h in r["validation"]] for r in per_seed])  # percent
            ax.plot(updates, val.mean(0), "o", color=color, markersize=3)
        ax.set_title(method)
        ax.set_xlabel("updates")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("SR (%): training (line), validation (o)")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def tune_report(
    methods, fields, grid_points, preset: str, setup: str, sweep_folder: Path, table: dict, results: dict
) -> tuple[str, dict]:
    """tune.md's text and tune.json's numbers from the arms' per-seed results: `table`
    {method: {grid point: arm}} over `grid_points` of the grid's `fields`, trained in
    `sweep_folder` at `preset` on `setup`."""
    chosen = {m: choose({p: results[a] for p, a in by_point.items()}) for m, by_point in table.items()}
    seeds = [r["seed"] for r in next(iter(results.values()))]
    md = (
        f"# Tuning {', '.join(fields)}: {', '.join(methods)}\n\n"
        f"Preset {preset}, setup {setup}, seeds {', '.join(map(str, seeds))}; each seed's model selected on "
        "validation, each method's value chosen by its seeds' mean validation SR (the test split does not choose). "
        "Mean ± sample std over seeds.\n\n## The grid\n\n"
    )
    text, rows = grid_table(table, results, chosen)
    md += text
    out = {"chosen": chosen, "grid": rows, "seeds": seeds, "best_vs_best": {}, "common": {}}
    pairs = pairs_of(methods)
    if pairs and len(seeds) > 1:
        best = {m: results[table[m][chosen[m]]] for m in methods}
        columns = [c for c in report.shown_columns(best) if c in (*report.TEST, report.TRAINING)]
        md += (
            "\n## Best vs best: each method at its own chosen value\n\n"
            + ", ".join(f"{m}: {chosen[m]}" for m in methods)
            + "\n"
        )
        text, out["best_vs_best"] = report.paired_report(best, pairs, columns, level="###")
        md += text
        for point in grid_points:
            at = {m: results[table[m][point]] for m in methods}
            md += f"\n## All at {point}\n"
            text, out["common"][point] = report.paired_report(at, pairs, columns, level="###")
            md += text
    chosen_arms = " ".join(table[m][chosen[m]] for m in methods)
    md += (
        f"\n![learning curves per value](tune_curves.png)\n\nThe arms' sweep: {sweep_folder} (its table1.md). "
        f"The paper's report with each method at its chosen value (the methods of its tables): "
        f"`python -m experiments.paper --arms {chosen_arms} --reuse {sweep_folder}`.\n"
    )
    return md, out
