"""The reporting of sweeps: Table 1's rows and Markdown, the pairs seed by seed (by path
length too), model selection, training diagnostics, and `paired_report`'s robust statistics
(IQM, P(B > A), Holm, MDE). Pure functions of the per-seed results a sweep writes
(`methods/<method>/results.json`); the programs (sweep, compare, tune, paper) print them."""

from __future__ import annotations


import numpy as np

from experiments.reporting import stats, tables
from experiments.reporting.tables import markdown_table

COLUMNS, HOUSE_COLUMNS = tables.RESULT_COLUMNS, tables.HOUSE_COLUMNS  # houses' results have both


# Training diagnostics kept per seed and chunk (the chunk's mean), in results.json: what
# the value baseline explains, how spread the advantages are, the gradient's size, the
# policy's entropy (why a critic helps or costs, docs/mechanism.md).
DIAGNOSTICS = (
    "losses/value_loss",
    "losses/explained_variance",
    "losses/advantage_std",
    "losses/grad_norm",
    "losses/entropy",
    "charts/noise_variance",
    "imagination/loss",
)

# An auxiliary target's (`foresit_jax.imagination`'s targets), recorded and shown where an arm has one:
# its loss, the share of valid steps it labels, and its gradient's norm at s_t over the
# actor-critic's.
TARGET_DIAGNOSTICS = ("losses/aux_loss", "charts/aux_labelled_fraction", "losses/aux_grad_ratio")


def diagnostic_label(name: str) -> str:
    """A table's column name for a diagnostic of `DIAGNOSTICS`: 'value_loss', ..., 'f_w loss'."""
    return "f_w loss" if name == "imagination/loss" else name.split("/")[-1]


def recorded_diagnostics(results: dict[str, list[dict]]) -> tuple[str, ...]:
    """`DIAGNOSTICS`, then the `TARGET_DIAGNOSTICS` some seed of `results` recorded."""
    recorded = {n for rs in results.values() for r in rs for n in (r.get("diagnostics") or {})}
    return DIAGNOSTICS + tuple(n for n in TARGET_DIAGNOSTICS if n in recorded)


def table(results_by_method: dict[str, list[dict]], room: str = "overall") -> list[dict]:
    """Rows of Table 1: per method, each column's mean, sample std and 95% confidence
    interval over seeds (`experiments.reporting.stats.summary`; `results_by_method`: per method, one
    test result per seed)."""
    rows = []
    for method, per_seed in results_by_method.items():
        row = {"method": method, "seeds": len(per_seed)}
        for col in COLUMNS + tuple(c for c in HOUSE_COLUMNS if c in per_seed[0][room]):
            s = stats.summary([np.nan if r[room][col] is None else r[room][col] for r in per_seed])
            row.update({f"{col} {k}": s[k] for k in ("mean", "std", "ci_low", "ci_high")})
        rows.append(row)
    return rows


def mean_std_ci(row: dict, col: str) -> str:
    if not np.isfinite(row[f"{col} mean"]):
        return "n/a"
    if not np.isfinite(row[f"{col} std"]):
        return f"{row[f'{col} mean']:.2f}"
    return (
        f"{row[f'{col} mean']:.2f} ± {row[f'{col} std']:.2f} [{row[f'{col} ci_low']:.1f}, {row[f'{col} ci_high']:.1f}]"
    )


def table_markdown(rows: list[dict], title: str) -> str:
    columns = [c for c in COLUMNS + HOUSE_COLUMNS if rows and f"{c} mean" in rows[0]]
    cells = [[tables.arm_label(row["method"]), *(mean_std_ci(row, c) for c in columns)] for row in rows]
    note = "mean ± sample std [95% confidence interval, Student t] over seeds"
    if any(tables.arm_label(row["method"]) != row["method"] for row in rows):
        note += "; " + tables.PRIVILEGED_NOTE
    return f"# {title}\n\n" + markdown_table(cells, ["Method", *columns]) + f"\n({note})\n"


def paired_markdown(results_by_method: dict[str, list[dict]], room: str = "overall") -> str:
    """Each method against the first, seed by seed (the same seeds and test episodes):
    the mean difference of SR and SPL, its 95% interval and the paired t-test's p."""
    methods = list(results_by_method)
    cells = []
    for method in methods[1:]:
        cell = [f"{tables.arm_label(method)} - {tables.arm_label(methods[0])}"]
        for col in ("SR", "SPL"):
            base, other = ([r[room][col] for r in results_by_method[m]] for m in (methods[0], method))
            p = stats.paired(base, other)
            p_value = f"{p['p']:.3f}" if np.isfinite(p["p"]) else "n/a"
            cell += [f"{p['diff']:+.2f} [{p['ci_low']:+.1f}, {p['ci_high']:+.1f}]", p_value, stats.verdict(p)]
        cells.append(cell)
    header = [
        "Methods",
        "SR difference [95% CI]",
        "p (SR)",
        "higher SR",
        "SPL difference [95% CI]",
        "p (SPL)",
        "higher SPL",
    ]
    return "## Paired over seeds (same seeds, same test episodes)\n\n" + markdown_table(cells, header) + "\n"


def rate(x) -> float:
    """A rate read back from JSON: None (an empty bucket, written as null) is NaN."""
    return np.nan if x is None else float(x)


def paired_by_length(results: dict[str, list[dict]], base: str, other: str) -> list[tuple[str, int, dict, dict]]:
    """Per bucket of L^g (`envs.metrics.LENGTH_BUCKETS_OF` the layout, in order), `other`
    against `base` seed by seed on each seed's selected model: (bucket, the test episodes
    in it summed over `base`'s seeds, `stats.paired` of SR, of SPL)."""
    buckets = results[base][0]["selected"]["by_length"]
    return [
        (
            bucket,
            sum(r["selected"]["by_length"][bucket]["episodes"] for r in results[base]),
            *(
                stats.paired(
                    *([rate(r["selected"]["by_length"][bucket][col]) for r in results[m]] for m in (base, other))
                )
                for col in ("SR", "SPL")
            ),
        )
        for bucket in buckets
    ]


def by_length_markdown(results: dict[str, list[dict]]) -> str:
    """SR and SPL by L^g bucket of each seed's selected model (mean ± std over seeds), and
    each method against the first per bucket, paired; '' without a second method and seed."""
    methods = list(results)
    if len(methods) < 2 or len(results[methods[0]]) < 2:
        return ""

    def mean_std(method, bucket, col):  # over the seeds with episodes in the bucket
        x = np.array([rate(r["selected"]["by_length"][bucket][col]) for r in results[method]])
        x = x[~np.isnan(x)]
        return "n/a" if not len(x) else f"{x.mean():.1f}" + (f" ± {x.std(ddof=1):.1f}" if len(x) > 1 else "")

    def pair(p):
        return "n/a" if not np.isfinite(p["diff"]) else f"{p['diff']:+.1f} [{p['ci_low']:+.1f}, {p['ci_high']:+.1f}]"

    buckets = list(results[methods[0]][0]["selected"]["by_length"])
    cells = [
        [bucket, *(f"{mean_std(m, bucket, 'SR')} / {mean_std(m, bucket, 'SPL')}" for m in methods)]
        for bucket in buckets
    ]
    md = (
        "## By optimal path length L^g: SR / SPL (mean ± sample std over seeds)\n\n"
        + markdown_table(cells, ["L^g", *methods])
        + "\n"
    )
    for other in methods[1:]:
        rows = [
            [bucket, episodes, pair(sr), stats.verdict(sr), pair(spl), stats.verdict(spl)]
            for bucket, episodes, sr, spl in paired_by_length(results, methods[0], other)
        ]
        header = ["L^g", "episodes (all seeds)", "SR difference [95% CI]", "higher SR", "SPL difference", "higher SPL"]
        md += f"\n### {other} - {methods[0]}, paired per bucket\n\n" + markdown_table(rows, header) + "\n"
    return md


def selection_markdown(results: dict[str, list[dict]]) -> str:
    """Test SR of the model selected on validation against the last model, per method
    (mean ± std over seeds) and per seed."""
    cells = []
    for method, per_seed in results.items():
        sr = [stats.summary([r[k]["overall"]["SR"] for r in per_seed]) for k in ("selected", "last")]
        seeds = ", ".join(
            f"{r['seed']}: {r['selected']['overall']['SR']:.1f} / {r['last']['overall']['SR']:.1f}"
            f" (update {r['selected_update']})"
            for r in per_seed
        )
        cells.append(
            [method, *(f"{s['mean']:.2f}" + (f" ± {s['std']:.2f}" if np.isfinite(s["std"]) else "") for s in sr), seeds]
        )
    header = ["Method", "SR, selected", "SR, last", "per seed: selected / last (selected update)"]
    return "## Model selection: the model of the best validation SR against the last one, test split\n\n" + (
        markdown_table(cells, header) + "\n"
    )


def diagnostics_markdown(results: dict[str, list[dict]]) -> str:
    """Training diagnostics (`DIAGNOSTICS`) per method: the mean over seeds of each
    chunk's mean, at the first, middle and last chunk; '' when no seed recorded any."""
    rows, shown = [], recorded_diagnostics(results)
    for method, per_seed in results.items():
        recorded = [r.get("diagnostics") or {} for r in per_seed]
        names = [n for n in shown if all(n in d for d in recorded)]
        if not names:
            continue
        chunks = len(recorded[0][names[0]])
        picks = sorted({0, chunks // 2, chunks - 1})
        for i in picks:
            cells = [f"{np.mean([d[n][i] for d in recorded]):.3g}" if n in names else "" for n in shown]
            rows.append([method, f"{i + 1}/{chunks}", *cells])
    if not rows:
        return ""
    header = ["Method", "chunk", *map(diagnostic_label, shown)]
    return "## Training diagnostics (mean over seeds of each chunk's mean)\n\n" + markdown_table(rows, header) + "\n"


TEST = ("SR", "SPL", "SR>=5")


TRAINING = "training SR"


# The area under the validation SR curve, as a mean: the trapezoid over the updates at
# which the validation split was evaluated (every chunk), divided by their span (%). It
# says how fast an arm learned, where the selected model's test SR says only how far it
# got (the budget branch of docs/plans/ceiling_channels.md asks for both).
VALIDATION_AREA = "validation SR area"


def validation_area(validation: list[dict]) -> float:
    """The mean of one seed's validation SR curve over its span (%): `validation`, the
    evaluations `[{"update": u, "SR": sr, ...}]` (results.json), trapezoid over u / span;
    the one SR for one evaluation; NaN for none or an empty bucket."""
    points = sorted((v["update"], rate(v["SR"])) for v in validation)
    if not points:
        return np.nan
    updates, sr = (np.array(x, float) for x in zip(*points))
    if len(points) == 1:
        return float(sr[0])
    return float(np.trapezoid(sr, updates) / (updates[-1] - updates[0]))


def values(per_seed: list[dict], column: str, last: int = 250) -> np.ndarray:
    """One value per seed: a test column of the selected model, the training success rate
    (%) over the `last` updates, the area under the validation SR curve (`validation_area`),
    or the last chunk's mean of a diagnostic (NaN if unrecorded)."""
    if column in TEST:
        return np.array([rate(r["selected"]["overall"][column]) for r in per_seed])
    if column == TRAINING:
        return np.array([100 * np.mean(r["training_success_rate"][-last:]) for r in per_seed])
    if column == VALIDATION_AREA:
        return np.array([validation_area(r.get("validation") or []) for r in per_seed])
    return np.array([(r.get("diagnostics") or {}).get(column, [np.nan])[-1] for r in per_seed], float)


def format_pair(p: dict) -> str:
    """A `stats.paired` result as "+d.dd [+lo, +hi]" (no interval for one seed; n/a when undefined)."""
    if not np.isfinite(p["diff"]):
        return "n/a"
    ci = f" [{p['ci_low']:+.2f}, {p['ci_high']:+.2f}]" if np.isfinite(p["ci_low"]) else ""
    return f"{p['diff']:+.2f}{ci}"


def format_mean_std(x: np.ndarray) -> str:
    """ "mean ± sample std" of the finite values of `x` (n/a when there are none)."""
    x = x[np.isfinite(x)]
    if not len(x):
        return "n/a"
    return f"{x.mean():.3g}" + (f" ± {x.std(ddof=1):.2g}" if len(x) > 1 else "")


def _interval(point: float, low: float, high: float, digits: int = 1) -> str:
    return f"{point:.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]"


def _robust(results: dict, pairs: list, out: dict, level: str = "##") -> str:
    """The robust table of the pairs (see the module docstring); adds "robust" to out["pairs"]."""
    rows = []
    for column in ("SR", "SPL"):
        family = [out["pairs"][f"{b} - {a}"][column]["p"] for a, b in pairs]
        adjusted = stats.holm(family)
        for (a, b), p_holm in zip(pairs, adjusted):
            x, y = values(results[a], column), values(results[b], column)
            iqm_a, iqm_b = (stats.stratified_bootstrap_ci(stats.iqm, v) for v in (x, y))
            poi = stats.stratified_bootstrap_ci(stats.probability_of_improvement, y, x)
            mde = stats.minimum_detectable_effect(float(np.std(y - x, ddof=1)) if len(x) > 1 else np.nan, len(x))
            name = f"{b} - {a}"
            out["pairs"][name].setdefault("robust", {})[column] = {
                "iqm_a": iqm_a,
                "iqm_b": iqm_b,
                "probability_of_improvement": poi,
                "p_holm": float(p_holm),
                "mde": mde,
            }
            rows.append(
                [
                    name,
                    column,
                    _interval(*iqm_a),
                    _interval(*iqm_b),
                    _interval(*poi, digits=2),
                    f"{p_holm:.3f}" if np.isfinite(p_holm) else "n/a",
                    f"{mde:.1f}" if np.isfinite(mde) else "n/a",
                ]
            )
    return (
        f"\n{level} What these seeds can tell: IQM and P(B > A) [95% stratified bootstrap], Holm over the pairs, "
        "the minimum detectable effect (80% power)\n\n"
        + markdown_table(rows, ["B - A", "", "IQM of A", "IQM of B", "P(B > A)", "p (Holm)", "MDE"])
        + "\n"
    )


def shown_columns(results: dict, last: int = 250) -> list[str]:
    """The columns of `TEST`, the training SR, the validation curve's area and
    `DIAGNOSTICS` that some seed recorded."""
    columns = (*TEST, TRAINING, VALIDATION_AREA, *DIAGNOSTICS, *TARGET_DIAGNOSTICS)
    return [c for c in columns if any(np.isfinite(values(rs, c, last)).any() for rs in results.values())]


def paired_report(
    results: dict, pairs: list, columns: list[str], last: int = 250, level: str = "##"
) -> tuple[str, dict]:
    """Markdown and numbers of `pairs` ([(A, B)] for B - A, the methods of `results`,
    same seeds) on `columns`: the seed-by-seed table, then `_robust`'s. The pairs are one
    family for Holm's correction. Returns (markdown, {"B - A": {column: stats.paired,
    "robust": {...}}})."""
    out: dict = {"pairs": {}}
    cells = []
    for a, b in pairs:
        name = f"{b} - {a}"
        out["pairs"][name] = {
            c: stats.paired(values(results[a], c, last), values(results[b], c, last)) for c in columns
        }
        cells.append(
            [
                f"{tables.arm_label(b)} - {tables.arm_label(a)}",
                *(format_pair(out["pairs"][name][c]) for c in columns),
                stats.verdict(out["pairs"][name]["SR"]),
            ]
        )
    names = [diagnostic_label(c) for c in columns]
    md = (
        f"\n{level} Paired seed by seed: difference [95% CI]\n\n"
        + markdown_table(cells, ["methods", *names, "higher SR"])
        + "\n"
    )
    md += _robust(results, pairs, out, level)
    return md, out["pairs"]
