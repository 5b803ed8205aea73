"""experiments.reporting.stats against hand computations (a t table, the closed form of the t
distribution with 2 degrees of freedom), scipy's own paired test, and invariants."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats as scipy_stats

from experiments.reporting import stats


def test_summary_by_hand():
    s = stats.summary([1, 2, 3, 4, 5])
    std = math.sqrt(2.5)  # sum of squared deviations 10, over n - 1 = 4
    half = 2.776 * std / math.sqrt(5)  # t_{0.975, 4} = 2.776 from a t table
    assert s["n"] == 5 and s["mean"] == 3 and s["std"] == pytest.approx(std)
    assert s["ci_low"] == pytest.approx(3 - half, abs=2e-3) and s["ci_high"] == pytest.approx(3 + half, abs=2e-3)


def test_summary_leaves_out_nan_and_reports_an_unknown_spread_as_nan():
    assert stats.summary([2.0, float("nan"), 4.0])["n"] == 2
    one = stats.summary([7.0])
    assert one["mean"] == 7.0 and all(math.isnan(one[k]) for k in ("std", "ci_low", "ci_high"))
    assert stats.summary([])["n"] == 0 and math.isnan(stats.summary([])["mean"])


def test_paired_by_hand_and_against_scipy():
    a, b = [1.0, 2.0, 3.0], [2.0, 4.0, 5.0]  # differences 1, 2, 2
    p = stats.paired(a, b)
    # mean 5/3, sample std sqrt(1/3), t = (5/3) / (sqrt(1/3) / sqrt(3)) = 5 with 2 dof;
    # for 2 dof the CDF is 1/2 + t / (2 sqrt(t^2 + 2)).
    p_hand = 2 * (0.5 - 5 / (2 * math.sqrt(27)))
    assert p["diff"] == pytest.approx(5 / 3) and p["p"] == pytest.approx(p_hand)
    assert p["p"] == pytest.approx(scipy_stats.ttest_rel(b, a).pvalue)
    assert p["ci_low"] > 0  # t_{0.975, 2} = 4.303: 5/3 - 4.303 / 3 = 0.232
    assert p["ci_low"] == pytest.approx(5 / 3 - 4.303 * math.sqrt(1 / 3) / math.sqrt(3), abs=1e-3)
    with pytest.raises(ValueError, match="one value per seed"):
        stats.paired([1.0, 2.0], [1.0])


def test_verdicts():
    assert stats.verdict({"ci_low": 0.5, "ci_high": 2.0}) == "holds"
    assert stats.verdict({"ci_low": -2.0, "ci_high": -0.5}) == "does not hold"
    assert stats.verdict({"ci_low": -1.0, "ci_high": 2.0}) == "cannot tell at this budget"
    assert stats.verdict({"ci_low": float("nan"), "ci_high": float("nan")}) == "cannot tell at this budget"
    assert stats.verdict({"ci_low": -2.0, "ci_high": -0.5}, claim_positive=False) == "holds"
    assert stats.verdict(stats.paired([1.0, 2.0, 3.0], [2.0, 3.0, 4.0])) == "cannot tell at this budget"  # no spread


finite = st.floats(-100, 100, allow_nan=False)


@settings(max_examples=50, deadline=None)
@given(st.lists(finite, min_size=2, max_size=8), finite)
def test_the_interval_holds_the_mean_and_moves_with_a_shift(values, shift):
    s, moved = stats.summary(values), stats.summary(np.asarray(values) + shift)
    assert s["ci_low"] <= s["mean"] <= s["ci_high"]
    for k in ("mean", "ci_low", "ci_high"):
        assert moved[k] == pytest.approx(s[k] + shift, abs=1e-6)
    assert moved["std"] == pytest.approx(s["std"], abs=1e-6)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(finite, finite), min_size=2, max_size=8))
def test_swapping_the_methods_flips_the_difference(pairs):
    a, b = np.array(pairs).T
    ab, ba = stats.paired(a, b), stats.paired(b, a)
    assert ab["diff"] == pytest.approx(-ba["diff"], abs=1e-9)
    assert ab["ci_low"] == pytest.approx(-ba["ci_high"], abs=1e-6)
    assert ab["p"] == pytest.approx(ba["p"], nan_ok=True)
