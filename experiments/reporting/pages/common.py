"""What the page modules share: the formats of their figures (a signed difference with its
interval, `signed` being `verdicts.signed` as `Verdict.figures` writes it; a bootstrap's
interval, mean ± std, per-seed values and their span, a table) and the
Holm-family helpers that give the rule's words (`verdicts.verdict`) to a family of paired
differences, to a family of `registry.Pair`s (judged once per `registry.Archives`), to a
probe's condition against the policy as trained, and the words as a sentence.

Reading the archives is `registry.Archives`'; the pages' own rules (results.md's 90%
interval beside a "level", the channels plan's rules 1-3) stay in their page's module.
"""

from __future__ import annotations

import weakref
from typing import Sequence

import numpy as np

from experiments.reporting import stats
from experiments.reporting.tables import markdown_table
from experiments.reporting.registry import PAPER_MARGIN, Archives, Pair, same_seeds, values
from experiments.reporting.verdicts import Verdict, family_verdicts, signed, verdict


# ---------------------------------------------------------------------- formats
def interval(mean: float, low: float, high: float, digits: int = 1) -> str:
    """A difference and its interval, "+1.4 [-2.0, +4.7]"."""
    return f"{signed(mean, digits)} [{signed(low, digits)}, {signed(high, digits)}]"


def figures(p: dict, digits: int = 1) -> str:
    """A `stats.paired` result's mean difference and 95% interval, as `Verdict.figures`."""
    return interval(p["diff"], p["ci_low"], p["ci_high"], digits)


def paired_figures(a, b, digits: int = 1) -> str:
    """B - A paired over seeds, "+d.d [+lo, +hi]"."""
    return figures(stats.paired(a, b), digits)


def bootstrap(t, digits: int = 1) -> str:
    """A bootstrap's (point, low, high), unsigned, "62.7 [55.8, 67.3]"."""
    return f"{t[0]:.{digits}f} [{t[1]:.{digits}f}, {t[2]:.{digits}f}]"


def gain(r: dict) -> str:
    """`experiments.foresight`'s gain from the target (a fraction, with its bootstrap
    interval `gain_ci`), in points: "+3.1 [+2.1, +4.1]"."""
    lo, hi = r["gain_ci"]
    return interval(100 * r["gain"], 100 * lo, 100 * hi)


def mean_std(x) -> str:
    """The mean and the sample std (ddof 1) of the finite values of `x`, "61.2 ± 3.4"."""
    s = stats.summary(x)
    return f"{s['mean']:.1f} ± {s['std']:.1f}"


def seed_by_seed(x, digits: int = 1) -> str:
    """Per-seed values, "61.2 / 58.0 / 64.1"."""
    return " / ".join(f"{v:.{digits}f}" for v in x)


def span(x, digits: int = 2, signs: bool = True) -> str:
    """The smallest and the largest of `x`, "+0.19 to +0.24" (unsigned: "19 to 24")."""
    fmt = f"{{:{'+' if signs else ''}.{digits}f}}"
    return f"{fmt.format(min(x))} to {fmt.format(max(x))}"


def table(header: Sequence[str], rows: Sequence[Sequence[str]], tight: bool = False) -> str:
    """A markdown table (`tables.markdown_table`) with its last newline; an empty cell is
    "|  |", or "| |" when `tight`."""
    if not tight:
        return markdown_table(rows, header) + "\n"

    def line(cells: Sequence[str]) -> str:
        return "|" + "|".join(f" {c} " if c else " " for c in cells) + "|"

    return "\n".join([line(header), "|" + "---|" * len(header), *map(line, rows)]) + "\n"


def cells(v: Verdict) -> list[str]:
    """A verdict's two cells: the figures and the rule's words."""
    return [v.figures(), v.words()]


def said(v: Verdict, metric: str = "", holm: bool = False) -> str:
    """ "SR +2.7 [-2.1, +7.5]: cannot tell (MDE 6.4)", with Holm's p where a family was judged."""
    return f"{metric or v.metric} {v.figures()}: {v.words()}" + (f", Holm p {v.p:.3f}" if holm else "")


# ---------------------------------------------------------------------- verdicts and Holm families
def alone(diffs, metric: str, margin: float = PAPER_MARGIN) -> Verdict:
    """The rule's verdict on one comparison's per-seed differences `diffs`, judged alone."""
    return verdict(diffs, metric, margin)


def verdicts_of(diffs: Sequence, metric: str, margin: float = PAPER_MARGIN, holm: bool = True) -> list[Verdict]:
    """`verdicts.family_verdicts` at the paper's margin by default: with `holm` and more than one
    comparison, one Holm family; else each alone."""
    return family_verdicts(diffs, metric, margin, holm)


def differences(results: dict[str, list[dict]], a: str, b: str, metric: str) -> np.ndarray:
    """B - A on `metric`, seed by seed, of two arms of `results` ({arm: per-seed results})."""
    same_seeds(results[a], results[b], f"{b} - {a}")
    return values(results[b], metric) - values(results[a], metric)


def family(results: dict[str, list[dict]], pairs, metric: str, margin: float = PAPER_MARGIN) -> list[Verdict]:
    """The rule's verdicts on B - A of each (A, B) of `pairs` (arms of `results`), one Holm family."""
    return verdicts_of([differences(results, a, b, metric) for a, b in pairs], metric, margin)


def by_pair(results: dict[str, list[dict]], pairs, metrics=("SR", "SPL")) -> dict[str, dict[tuple[str, str], Verdict]]:
    """{metric: {(A, B): the rule's verdict}}, `pairs` one Holm family on each metric (`family`)."""
    return {m: dict(zip(pairs, family(results, pairs, m))) for m in metrics}


_JUDGED: "weakref.WeakKeyDictionary[Archives, dict]" = weakref.WeakKeyDictionary()


def judged(
    archives: Archives, pairs: Sequence[Pair], metric: str, holm: bool = True, margin: float = PAPER_MARGIN
) -> list[Verdict]:
    """Each `Pair`'s verdict on `metric` (`verdicts_of`: with `holm`, one family), judged once per `archives`."""
    key = (tuple(pairs), metric, holm, margin)
    done = _JUDGED.setdefault(archives, {})
    if key not in done:
        done[key] = verdicts_of([p.differences(archives, metric) for p in pairs], metric, margin, holm)
    return done[key]


def probe_condition(per_seed: list[dict], condition: str) -> Verdict:
    """An `experiments.probe` condition's SR minus the policy's SR as trained, paired over
    the probed seeds, judged alone."""
    base = np.array([r["sr"]["trained"] for r in per_seed])
    return alone(np.array([r["sr"][condition] for r in per_seed]) - base, "SR")
