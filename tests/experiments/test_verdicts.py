"""experiments.reporting.verdicts: the project's rule for a comparison's words, against
hand-computed Student-t intervals (t quantiles from tables: t_{0.975, 2} = 4.3027,
t_{0.95, 2} = 2.9200)."""

import math

import numpy as np
import pytest

from experiments.reporting import verdicts
from experiments.reporting.verdicts import WORDS, verdict


def test_the_intervals_are_the_hand_computed_ones():
    v = verdict([1.0, 2.0, 3.0], "SR", margin=4.0)
    half95, half90 = 4.3027 / math.sqrt(3), 2.9200 / math.sqrt(3)
    np.testing.assert_allclose(v.ci95, (2 - half95, 2 + half95), atol=1e-4)
    np.testing.assert_allclose(v.ci90, (2 - half90, 2 + half90), atol=1e-4)
    assert v.n == 3 and v.diff == 2.0


@pytest.mark.parametrize(
    "diffs,margin,higher,word",
    [
        ([1.0, 2.0, 3.0], 4.0, True, "level"),  # 95% holds 0; 90% [0.31, 3.69] inside ±4
        ([1.0, 2.0, 3.0], 3.0, True, "cannot tell"),  # 90% reaches past +3
        ([3.0, 4.0, 5.0], 3.8, True, "helps"),
        ([-5.0, -4.0, -3.0], 3.8, True, "costs"),
        ([-5.0, -4.0, -3.0], 3.8, False, "helps"),  # a lower-is-better metric (an error, a length)
        ([1.0, 1.0, 1.0], 3.8, True, "cannot tell"),  # no spread, no interval
        ([2.0], 3.8, True, "cannot tell"),  # one seed
    ],
)
def test_the_rule(diffs, margin, higher, word):
    assert verdict(diffs, "SR", margin, higher_is_better=higher).word == word


def test_a_resolved_effect_inside_the_margin_says_both():
    v = verdict([0.9, 1.0, 1.1, 1.0], "SR", margin=3.8)
    assert v.word == "helps" and v.within_margin
    assert v.sentence("x - a3c").endswith("helps, within ±3.8")


def test_holm_can_withhold_a_resolved_word():
    alone = verdict([3.0, 4.0, 5.0], "SR", 3.8)
    assert alone.word == "helps" and alone.p < 0.05
    assert verdict([3.0, 4.0, 5.0], "SR", 3.8, p_adjusted=0.09).word == "cannot tell"


def test_cannot_tell_carries_the_mde():
    v = verdict([-2.0, 5.0, 1.0, -1.0, 4.0], "SR", 1.0)
    assert v.word == "cannot tell" and v.mde > 0
    # 1.4 ± t_{0.975, 4} * 3.0496 / sqrt(5) = 1.4 ± 2.7764 * 1.3638 = [-2.39, +5.19]
    assert v.sentence("b - a") == f"b - a, SR: +1.4 [-2.4, +5.2]: cannot tell (MDE {v.mde:.1f})"
    assert v.word in WORDS


@pytest.mark.parametrize("margin", [0.0, -1.0, math.nan, "3.8"])
def test_a_margin_must_be_declared_positive(margin):
    with pytest.raises(ValueError, match="margin must be a positive number"):
        verdict([1.0, 2.0], "SR", margin)


def test_a_family_is_judged_with_holm_and_a_family_of_one_alone():
    """`family_verdicts`: two gains each clear of 0 alone (p 0.030 and 0.027 on five seeds) lose
    their word in one Holm family (both adjusted to 0.054, twice the smaller); one comparison, or holm=False, is
    judged alone; a comparison without spread (a NaN p) is judged as alone, not refused."""
    a, b = [12, 1, 9, 4, 14], [3, 0.5, 4, 1, 2.5]
    assert [v.word for v in verdicts.family_verdicts([a, b], "SR", 3.8, holm=False)] == ["helps", "helps"]
    together = verdicts.family_verdicts([a, b], "SR", 3.8)
    assert [v.word for v in together] == ["cannot tell", "level"]
    assert [v.p for v in together] == pytest.approx([2 * 0.02690, 2 * 0.02690], abs=1e-4)
    assert verdicts.family_verdicts([a], "SR", 3.8)[0].word == "helps"
    flat = verdicts.family_verdicts([a, [2.0] * 5], "SR", 3.8)
    assert flat[1].word == "cannot tell" and flat[1].words() == "cannot tell (no spread)"
