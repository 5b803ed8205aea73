"""Any two methods of a sweep, paired: `python -m experiments.compare --run runs/x --pairs a3c:a3c+critic`.

A sweep's table1.md pairs every method with the first on test SR and SPL. The mechanism
studies (docs/mechanism.md) also ask about any two methods, about what training did, and
about how one difference changes from one setting to another. From a sweep folder's
finished methods (`methods/<method>/results.json`) this prints, as Markdown:

* per method: test SR of each seed's selected model, mean ± sample std of SR, SPL, SR>=5,
  the training success rate over the last `--last` updates, the last chunk's training
  diagnostics (`sweep.DIAGNOSTICS`, those recorded), and the experience each seed had
  where the sweep counted it;
* per `--pairs A:B`: B - A seed by seed (`experiments.stats.paired`: mean difference, 95%
  t interval, p, verdict) on each of those columns;
* per pair, on SR and SPL, what five seeds can tell (`experiments.stats`): each arm's
  interquartile mean with a 95% stratified-bootstrap interval, the probability that a seed
  of B beats a seed of A (with its interval), the paired p-value Holm-corrected over the
  pairs of this call (the declared family), and the minimum difference the paired t-test
  over these seeds detects with 80% power (beside a "cannot tell", the effect it could
  have seen);
* per `--did A:B:C:D`: (D - C) - (B - A) seed by seed on test SR, SPL and SR>=5, e.g. the
  critic's cost in one layout against its cost in another.

Pairs need the same seeds in both methods (a sweep's methods have them).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from experiments import runs, stats
from experiments.sweep import DIAGNOSTICS, diagnostic_label, rate
from experiments.tables import markdown_table

TEST = ("SR", "SPL", "SR>=5")
TRAINING = "training SR"


@dataclasses.dataclass(frozen=True)
class Args:
    """Pair any two methods of a sweep seed by seed, on test and training numbers."""

    run: Path
    """A sweep folder (experiments.sweep or one setup of experiments.paper)."""
    pairs: tuple[str, ...] = ()
    """'A:B' for B - A (method names as the sweep's methods/ folder has them)."""
    did: tuple[str, ...] = ()
    """'A:B:C:D' for the difference of differences (D - C) - (B - A)."""
    last: int = 250
    """The training success rate is the mean over this many last updates."""


def load(run: Path) -> dict[str, list[dict]]:
    """Every finished method of the sweep folder `run`: its per-seed results, in name order."""
    folder = Path(run) / "methods"
    if not folder.is_dir():
        raise runs.UserError(f"{run} is not a sweep folder (it has no methods/): give --run the folder a sweep wrote")
    found = {m.name: runs.read_json(m / "results.json")["results"]
             for m in sorted(folder.iterdir()) if (m / "results.json").is_file()}  # fmt: skip
    if not found:
        raise runs.UserError(f"{run} has no finished method yet (no methods/*/results.json)")
    return found


def values(per_seed: list[dict], column: str, last: int = 250) -> np.ndarray:
    """One value per seed: a test column of the selected model, the training success rate
    (%) over the `last` updates, or the last chunk's mean of a diagnostic (NaN if unrecorded)."""
    if column in TEST:
        return np.array([rate(r["selected"]["overall"][column]) for r in per_seed])
    if column == TRAINING:
        return np.array([100 * np.mean(r["training_success_rate"][-last:]) for r in per_seed])
    return np.array([(r.get("diagnostics") or {}).get(column, [np.nan])[-1] for r in per_seed], float)


def _split(spec: str, parts: int, flag: str, results: dict) -> list[str]:
    names = spec.split(":")
    if len(names) != parts:
        raise runs.UserError(f"{flag} {spec!r}: give {parts} method names joined by ':'")
    for name in names:
        if name not in results:
            raise runs.UserError(f"{flag}: {name!r} is not a finished method of this sweep; it has "
                                 + ", ".join(results))  # fmt: skip
    seeds = [[r["seed"] for r in results[n]] for n in names]
    if any(s != seeds[0] for s in seeds):
        raise runs.UserError(f"{flag} {spec!r}: the methods have different seeds ({seeds}); pairs need the same")
    return names


def _pair(p: dict) -> str:
    if not np.isfinite(p["diff"]):
        return "n/a"
    ci = f" [{p['ci_low']:+.2f}, {p['ci_high']:+.2f}]" if np.isfinite(p["ci_low"]) else ""
    return f"{p['diff']:+.2f}{ci}"


def _mean_std(x: np.ndarray) -> str:
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
                "iqm_a": iqm_a, "iqm_b": iqm_b, "probability_of_improvement": poi, "p_holm": float(p_holm), "mde": mde}
            rows.append([name, column, _interval(*iqm_a), _interval(*iqm_b), _interval(*poi, digits=2),
                         f"{p_holm:.3f}" if np.isfinite(p_holm) else "n/a",
                         f"{mde:.1f}" if np.isfinite(mde) else "n/a"])  # fmt: skip
    return (f"\n{level} What these seeds can tell: IQM and P(B > A) [95% stratified bootstrap], Holm over the pairs, "
            "the minimum detectable effect (80% power)\n\n"
            + markdown_table(rows, ["B - A", "", "IQM of A", "IQM of B", "P(B > A)", "p (Holm)", "MDE"]) + "\n")


def shown_columns(results: dict, last: int = 250) -> list[str]:
    """The columns of `TEST`, the training SR and `DIAGNOSTICS` that some seed recorded."""
    columns = (*TEST, TRAINING, *DIAGNOSTICS)
    return [c for c in columns if any(np.isfinite(values(rs, c, last)).any() for rs in results.values())]


def paired_report(results: dict, pairs: list, columns: list[str], last: int = 250, level: str = "##") -> tuple[str, dict]:
    """Markdown and numbers of `pairs` ([(A, B)] for B - A, the methods of `results`,
    same seeds) on `columns`: the seed-by-seed table, then `_robust`'s. The pairs are one
    family for Holm's correction. Returns (markdown, {"B - A": {column: stats.paired,
    "robust": {...}}})."""
    out: dict = {"pairs": {}}
    cells = []
    for a, b in pairs:
        name = f"{b} - {a}"
        out["pairs"][name] = {c: stats.paired(values(results[a], c, last), values(results[b], c, last)) for c in columns}
        cells.append([name, *(_pair(out["pairs"][name][c]) for c in columns), stats.verdict(out["pairs"][name]["SR"])])
    names = [diagnostic_label(c) for c in columns]
    md = (f"\n{level} Paired seed by seed: difference [95% CI]\n\n"
          + markdown_table(cells, ["methods", *names, "higher SR"]) + "\n")  # fmt: skip
    md += _robust(results, pairs, out, level)
    return md, out["pairs"]


def main(args: Args) -> dict:
    """Print the comparison; returns {"pairs": {"B - A": {column: stats.paired}},
    "did": {"(D - C) - (B - A)": {column: stats.paired}}}."""
    if args.last < 1:
        raise runs.UserError(f"--last {args.last}: give a positive number of updates")
    results = load(args.run)
    pairs = [_split(s, 2, "--pairs", results) for s in args.pairs]
    dids = [_split(s, 4, "--did", results) for s in args.did]
    shown = shown_columns(results, args.last)

    rows = []
    for method, per_seed in results.items():
        per = " / ".join(f"{x:.1f}" for x in values(per_seed, "SR"))
        counts = [r.get("counts") or {} for r in per_seed]
        experience = ("" if not all("frames/useful" in c for c in counts) else
                      ", ".join(f"{c['frames/useful'] / 1e6:.2f}M / {int(c['charts/episodes'])}" for c in counts))  # fmt: skip
        rows.append([method, ", ".join(str(r["seed"]) for r in per_seed), per,
                     *(_mean_std(values(per_seed, c, args.last)) for c in shown), experience])  # fmt: skip
    names = [diagnostic_label(c) for c in shown]
    md = (f"# {args.run}: per method (mean ± sample std over seeds)\n\n"
          + markdown_table(rows, ["method", "seeds", "SR per seed", *names, "frames / episodes per seed"]) + "\n"
          + f"(training SR: the last {args.last} updates; diagnostics: the last chunk's mean)\n")  # fmt: skip

    out: dict = {"pairs": {}, "did": {}}
    if pairs:
        text, out["pairs"] = paired_report(results, pairs, shown, args.last)
        md += text
    if dids:
        cells = []
        for a, b, c, d in dids:
            name = f"({d} - {c}) - ({b} - {a})"
            out["did"][name] = {col: stats.paired(*(values(results[y], col) - values(results[x], col)
                                                    for x, y in ((a, b), (c, d)))) for col in TEST}  # fmt: skip
            cells.append([name, *(_pair(out["did"][name][col]) for col in TEST),
                          *(f"{out['did'][name][col]['p']:.3f}" for col in TEST)])  # fmt: skip
        md += ("\n## Difference of differences, seed by seed [95% CI]\n\n"
               + markdown_table(cells, ["differences", *TEST, *(f"p ({c})" for c in TEST)]) + "\n")  # fmt: skip
    print(md)
    return out


def cli(argv=None) -> None:
    runs.run_cli(Args, main, argv)


if __name__ == "__main__":
    cli()
