"""Any two methods of a sweep, paired: `python -m experiments.compare --run runs/x --pairs a3c:a3c+critic`.

A sweep's table1.md pairs every method with the first on test SR and SPL. The mechanism
studies (docs/mechanism.md) also ask about any two methods, about what training did, and
about how one difference changes from one setting to another. From a sweep folder's
finished methods (`methods/<method>/results.json`) this prints, as Markdown:

* per method: test SR of each seed's selected model, mean ± sample std of SR, SPL, SR>=5,
  the training success rate over the last `--last` updates, the area under the validation
  SR curve (its mean over the evaluated updates, `report.validation_area`: how fast an arm
  learned, where the selected model's SR says how far it got), the last chunk's training
  diagnostics (`report.DIAGNOSTICS`, those recorded), and the experience each seed had
  where the sweep counted it;
* per `--pairs A:B`: B - A seed by seed (`experiments.reporting.stats.paired`: mean difference, 95%
  t interval, p, verdict) on each of those columns;
* per pair, on SR and SPL, what five seeds can tell (`experiments.reporting.stats`): each arm's
  interquartile mean with a 95% stratified-bootstrap interval, the probability that a seed
  of B beats a seed of A (with its interval), the paired p-value Holm-corrected over the
  pairs of this call (the declared family), and the minimum difference the paired t-test
  over these seeds detects with 80% power (beside a "cannot tell", the effect it could
  have seen);
* per `--did A:B:C:D`: (D - C) - (B - A) seed by seed on test SR, SPL and SR>=5, e.g. the
  critic's cost in one layout against its cost in another;
* per `--ceiling A:B:C`: the ceiling C - A (C a privileged arm, e.g. the oracle
  imagination over the critic alone A) and the share of it B closes, (B - A) / (C - A),
  with a paired bootstrap interval, only where the ceiling's interval excludes 0
  (`stats.share_closed`; docs/ceiling.md); otherwise "ceiling not resolved".

Pairs need the same seeds in both methods (a sweep's methods have them).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from experiments import errors, rundir
from experiments.reporting import stats
from experiments.reporting.report import (
    TEST,
    diagnostic_label,
    format_mean_std,
    format_pair,
    paired_report,
    shown_columns,
    values,
)
from experiments.reporting.tables import arm_label, markdown_table


@dataclasses.dataclass(frozen=True)
class Args:
    """Pair any two methods of a sweep seed by seed, on test and training numbers."""

    run: Path
    """A sweep folder (experiments.sweep or one setup of experiments.paper)."""
    pairs: tuple[str, ...] = ()
    """'A:B' for B - A (method names as the sweep's methods/ folder has them)."""
    did: tuple[str, ...] = ()
    """'A:B:C:D' for the difference of differences (D - C) - (B - A)."""
    ceiling: tuple[str, ...] = ()
    """'A:B:C': the ceiling C - A and the share of it B closes, (B - A) / (C - A), on SR and SPL."""
    last: int = 250
    """The training success rate is the mean over this many last updates."""


def _split(spec: str, parts: int, flag: str, results: dict) -> list[str]:
    names = spec.split(":")
    if len(names) != parts:
        raise errors.UserError(f"{flag} {spec!r}: give {parts} method names joined by ':'")
    for name in names:
        if name not in results:
            raise errors.UserError(
                f"{flag}: {name!r} is not a finished method of this sweep; it has " + ", ".join(results)
            )
    seeds = [[r["seed"] for r in results[n]] for n in names]
    if any(s != seeds[0] for s in seeds):
        raise errors.UserError(f"{flag} {spec!r}: the methods have different seeds ({seeds}); pairs need the same")
    return names


def main(args: Args) -> dict:
    """Print the comparison; returns {"pairs": {"B - A": {column: stats.paired}},
    "did": {"(D - C) - (B - A)": {column: stats.paired}}}."""
    if args.last < 1:
        raise errors.UserError(f"--last {args.last}: give a positive number of updates")
    results = rundir.sweep_results(args.run)
    pairs = [_split(s, 2, "--pairs", results) for s in args.pairs]
    dids = [_split(s, 4, "--did", results) for s in args.did]
    ceilings = [_split(s, 3, "--ceiling", results) for s in args.ceiling]
    shown = shown_columns(results, args.last)

    rows = []
    for method, per_seed in results.items():
        per = " / ".join(f"{x:.1f}" for x in values(per_seed, "SR"))
        counts = [r.get("counts") or {} for r in per_seed]
        experience = (
            ""
            if not all("frames/useful" in c for c in counts)
            else ", ".join(f"{c['frames/useful'] / 1e6:.2f}M / {int(c['charts/episodes'])}" for c in counts)
        )
        rows.append(
            [
                arm_label(method),
                ", ".join(str(r["seed"]) for r in per_seed),
                per,
                *(format_mean_std(values(per_seed, c, args.last)) for c in shown),
                experience,
            ]
        )
    names = [diagnostic_label(c) for c in shown]
    md = (
        f"# {args.run}: per method (mean ± sample std over seeds)\n\n"
        + markdown_table(rows, ["method", "seeds", "SR per seed", *names, "frames / episodes per seed"])
        + "\n"
        + f"(training SR: the last {args.last} updates; diagnostics: the last chunk's mean)\n"
    )

    out: dict = {"pairs": {}, "did": {}, "ceiling": {}}
    if pairs:
        text, out["pairs"] = paired_report(results, pairs, shown, args.last)
        md += text
    if dids:
        cells = []
        for a, b, c, d in dids:
            name = f"({d} - {c}) - ({b} - {a})"
            out["did"][name] = {
                col: stats.paired(*(values(results[y], col) - values(results[x], col) for x, y in ((a, b), (c, d))))
                for col in TEST
            }
            cells.append(
                [
                    name,
                    *(format_pair(out["did"][name][col]) for col in TEST),
                    *(f"{out['did'][name][col]['p']:.3f}" for col in TEST),
                ]
            )
        md += (
            "\n## Difference of differences, seed by seed [95% CI]\n\n"
            + markdown_table(cells, ["differences", *TEST, *(f"p ({c})" for c in TEST)])
            + "\n"
        )
    if ceilings:
        md += ceiling_markdown(results, ceilings, out["ceiling"])
    print(md)
    return out


def ceiling_markdown(results: dict, ceilings: list, out: dict) -> str:
    """The `--ceiling` table; fills out["C - A"] = {column: stats.share_closed}."""
    cells = []
    for a, b, c in ceilings:
        name = f"{c} - {a}"
        out[name] = {}
        for col in ("SR", "SPL"):
            base = values(results[a], col)
            share = stats.share_closed(values(results[b], col) - base, values(results[c], col) - base)
            out[name][col] = {**share, "arm": b}
            top = f"{share['ceiling']:+.1f} [{share['ceiling_low']:+.1f}, {share['ceiling_high']:+.1f}]"
            closed = (
                f"{share['share']:.2f} [{share['share_low']:.2f}, {share['share_high']:.2f}]"
                if share["resolved"]
                else "ceiling not resolved"
            )
            cells.append([name, col, top, b, closed])
    return (
        "\n## The ceiling and the share of it an arm closes (paired seeds; share: exact paired bootstrap [95%])\n\n"
        + markdown_table(cells, ["ceiling", "", "C - A [95% CI]", "arm B", "(B - A) / (C - A)"])
        + "\n"
    )


def cli(argv=None) -> None:
    errors.run_cli(Args, main, argv)


if __name__ == "__main__":
    cli()
