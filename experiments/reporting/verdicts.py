"""The project's one rule for the words a comparison earns (docs/results.md): the only
place it is stated, so that no page judges by hand.

Given the per-seed differences B - A of one metric (paired: the same seeds, the same
episodes), `verdict` says

* "helps" or "costs" when the 95% Student-t interval of the mean difference excludes 0
  (and, in a family of comparisons, Holm's adjusted p-value is below 0.05): the sign is
  read with the metric's direction (`higher_is_better`);
* "level" when it does not, and the 90% interval lies inside (-margin, +margin) (two
  one-sided tests at 5%: an equivalence claim needs the margin declared beforehand);
* "cannot tell" otherwise, with the minimum detectable effect (80% power, 5%, two-sided)
  beside it, the size of effect these seeds could have resolved.

A resolved effect whose 90% interval also lies inside the margin is "helps" (or "costs")
with `within_margin` set: the sentence says both.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Optional, Sequence

import numpy as np

from experiments.reporting import stats

EQUIVALENCE_LEVEL = 0.90
WORDS = ("helps", "costs", "level", "cannot tell")


class Verdict(NamedTuple):
    """One comparison's words and the figures they rest on."""

    word: str  # one of WORDS
    metric: str
    n: int  # seeds
    diff: float  # mean of B - A
    ci95: tuple[float, float]
    ci90: tuple[float, float]
    margin: float
    mde: float  # NaN with under two seeds or no spread
    within_margin: bool  # the 90% interval lies inside (-margin, +margin)
    p: float  # the paired t-test's p-value, Holm-adjusted when p_adjusted was given

    def figures(self) -> str:
        """The mean difference and its 95% interval, "+2.1 [-1.0, +5.2]"."""
        return f"{signed(self.diff)} [{signed(self.ci95[0])}, {signed(self.ci95[1])}]"

    def words(self) -> str:
        """The words the rule gives, with what they rest on: "cannot tell (MDE 4.4)",
        "level within ±3.8", "helps", "costs, within ±3.8"."""
        if self.word == "cannot tell":
            return f"cannot tell (MDE {self.mde:.1f})" if math.isfinite(self.mde) else "cannot tell (no spread)"
        if self.word == "level":
            return f"level within ±{self.margin:g}"
        return self.word + (f", within ±{self.margin:g}" if self.within_margin else "")

    def sentence(self, name: str = "B - A") -> str:
        """The verdict as the docs write it, e.g. "compass - a3c, SR: +2.1 [-1.0, +5.2]: cannot
        tell (MDE 4.4)"."""
        return f"{name}, {self.metric}: {self.figures()}: {self.words()}"


def signed(x: float, digits: int = 1) -> str:
    """`x` with its sign, "+2.1", "-0.4"."""
    return f"{x:+.{digits}f}"


def verdict(
    per_seed_differences,
    metric: str,
    margin: float,
    higher_is_better: bool = True,
    p_adjusted: Optional[float] = None,
) -> Verdict:
    """The words of one comparison (module docstring). per_seed_differences: B - A, one per
    seed; margin: the declared equivalence margin (> 0), in the metric's units; p_adjusted:
    Holm's adjusted p-value of this comparison in its family (None: alone)."""
    if not (isinstance(margin, (int, float)) and math.isfinite(margin) and margin > 0):
        raise ValueError(f"verdict: the margin must be a positive number, got {margin!r}")
    d95 = stats.summary(per_seed_differences, stats.LEVEL)
    d90 = stats.summary(per_seed_differences, EQUIVALENCE_LEVEL)
    n, diff = d95["n"], d95["mean"]
    lo, hi = d95["ci_low"], d95["ci_high"]
    lo90, hi90 = d90["ci_low"], d90["ci_high"]
    spread = n >= 2 and math.isfinite(d95["std"]) and d95["std"] > 0
    p = stats.paired([0.0] * n, list(_finite(per_seed_differences)))["p"] if n else math.nan
    if p_adjusted is not None:
        p = p_adjusted
    within = bool(spread and -margin < lo90 and hi90 < margin)
    resolved = bool(spread and (lo > 0 or hi < 0) and (p_adjusted is None or p_adjusted < 0.05))
    if resolved:
        better = (lo > 0) == higher_is_better
        word = "helps" if better else "costs"
    elif within:
        word = "level"
    else:
        word = "cannot tell"
    mde = stats.minimum_detectable_effect(d95["std"], n) if spread else math.nan
    return Verdict(word, metric, n, diff, (lo, hi), (lo90, hi90), float(margin), mde, within, p)


def family_verdicts(diffs: Sequence, metric: str, margin: float, holm: bool = True) -> list[Verdict]:
    """The rule's verdict on each comparison of a family (`diffs`: one comparison's per-seed
    differences each): with `holm` and more than one, Holm's adjusted p of each one's paired
    t-test (as `experiments.compare` adjusts them) decides "helps" and "costs"; else each alone."""
    if not holm or len(diffs) < 2:
        return [verdict(d, metric, margin) for d in diffs]
    adjusted = stats.holm([stats.paired(np.zeros(len(d)), d)["p"] for d in diffs])
    return [
        verdict(d, metric, margin, p_adjusted=float(p) if math.isfinite(p) else None) for d, p in zip(diffs, adjusted)
    ]


def _finite(values):
    return [float(v) for v in values if math.isfinite(float(v))]
