"""experiments.reporting.stats' robust statistics: against hand-computed values, a brute-force count,
a simulation, and rliable's own functions on fixed data (where rliable is installed)."""

import importlib.util
import math

import numpy as np
import pytest

from experiments.reporting import stats

needs_rliable = pytest.mark.skipif(
    importlib.util.find_spec("rliable") is None, reason="rliable is not installed (pip install rliable)"
)
RNG = np.random.default_rng(7)
SCORES = RNG.uniform(0, 100, size=(5, 4))  # 5 seeds x 4 room types
OTHER = RNG.uniform(10, 90, size=(7, 4))


def test_iqm_by_hand():
    # 8 values: the middle 4 (3, 4, 5, 6) are kept
    assert stats.iqm([8, 1, 7, 2, 6, 3, 5, 4]) == pytest.approx(4.5)
    assert stats.iqm([[1, 2], [3, 100]]) == pytest.approx(2.5)  # pooled over tasks: 2 and 3


def test_probability_of_improvement_by_brute_force():
    x, y = np.array([1.0, 2.0, 3.0]), np.array([2.0, 2.0])
    # pairs (x > y): 3>2 twice; ties 2=2 twice; of 6 pairs -> (2 + 0.5 * 2) / 6
    assert stats.probability_of_improvement(x, y) == pytest.approx(3 / 6)
    count = sum((a > b) + 0.5 * (a == b) for t in range(4) for a in SCORES[:, t] for b in OTHER[:, t])
    assert stats.probability_of_improvement(SCORES, OTHER) == pytest.approx(count / (4 * 5 * 7))
    assert stats.probability_of_improvement(SCORES, SCORES) == pytest.approx(0.5)


def test_holm_by_hand_and_nan_is_left_out():
    adjusted = stats.holm([0.01, 0.04, 0.03, math.nan, 0.5])
    # m = 4 finite: sorted 0.01, 0.03, 0.04, 0.5 -> 0.04, 0.09, max(0.09, 0.08), max(., 0.5)
    np.testing.assert_allclose(adjusted[[0, 2, 1, 4]], [0.04, 0.09, 0.09, 0.5])
    assert math.isnan(adjusted[3])


def test_minimum_detectable_effect_has_the_power_it_claims_in_a_simulation():
    n, sd = 5, 6.0
    mde = stats.minimum_detectable_effect(sd, n)
    # the textbook approximation (t quantiles, no noncentrality) is close
    approx = (2.7764451 + 0.9409646) * sd / math.sqrt(n)
    assert abs(mde - approx) / approx < 0.1
    rng = np.random.default_rng(0)
    d = rng.normal(mde, sd, size=(20000, n))
    t = d.mean(1) / (d.std(1, ddof=1) / math.sqrt(n))
    power = (np.abs(t) > 2.7764451).mean()
    assert power == pytest.approx(0.8, abs=0.015)
    assert math.isnan(stats.minimum_detectable_effect(sd, 1)) and math.isnan(stats.minimum_detectable_effect(0.0, 5))


def test_bootstrap_interval_covers_the_point_and_shrinks_with_more_runs(monkeypatch):
    monkeypatch.setattr(stats, "MIN_MONTE_CARLO", 500)  # SCORES' tasks are beyond the exact limit
    point, low, high = stats.stratified_bootstrap_ci(stats.iqm, SCORES, reps=500)
    assert low <= point <= high
    many = np.tile(SCORES, (20, 1))
    _, low_many, high_many = stats.stratified_bootstrap_ci(stats.iqm, many, reps=500)
    assert high_many - low_many < (high - low) / 2
    # stratified: a task's resampled runs come from that task only
    constant_tasks = np.tile(np.arange(4.0), (6, 1))  # task t always scores t
    assert stats.stratified_bootstrap_ci(lambda s: s.mean(), constant_tasks, reps=50)[1:] == (1.5, 1.5)


@needs_rliable
def test_iqm_and_probability_of_improvement_equal_rliables():
    from rliable import metrics

    assert stats.iqm(SCORES) == pytest.approx(metrics.aggregate_iqm(SCORES), rel=1e-12)
    assert stats.probability_of_improvement(SCORES, OTHER) == pytest.approx(
        metrics.probability_of_improvement(SCORES, OTHER), rel=1e-12
    )


# rliable 1.2.0's get_interval_estimates on SCORES and OTHER (20,000 stratified-bootstrap
# replicates, percentile intervals, the mean of 5 random states; rliable with arch 7.2.0 and
# pandas 2.3.3, since arch does not import beside pandas 3, the pinned stack's): the
# interval ends of the IQM varied by 0.14 between random states, those of the probability of
# improvement not at all (a statistic of few values).
RLIABLE_IQM = (58.8678103083495, 41.97467204151848, 74.39075642046922)
RLIABLE_POI = (0.65, 0.47857142857142854, 0.8071428571428572)


def test_bootstrap_intervals_equal_rliables_up_to_resampling_noise():
    point, low, high = stats.stratified_bootstrap_ci(stats.iqm, SCORES, reps=8000)
    assert point == pytest.approx(RLIABLE_IQM[0], rel=1e-12)
    assert low == pytest.approx(RLIABLE_IQM[1], abs=1.0) and high == pytest.approx(RLIABLE_IQM[2], abs=1.0)
    point, low, high = stats.stratified_bootstrap_ci(stats.probability_of_improvement, SCORES, OTHER, reps=8000)
    assert point == pytest.approx(RLIABLE_POI[0], rel=1e-12)
    assert low == pytest.approx(RLIABLE_POI[1], abs=0.015) and high == pytest.approx(RLIABLE_POI[2], abs=0.015)


def test_multisets_and_their_probabilities_count_every_ordered_resample():
    """Brute force: all n^n ordered draws, grouped by their counts."""
    import itertools
    from collections import Counter

    for n in (1, 3, 5):
        counts, probs = stats.multisets(n)
        assert len(counts) == math.comb(2 * n - 1, n) and (counts.sum(1) == n).all()
        brute = Counter(tuple(np.bincount(draw, minlength=n)) for draw in itertools.product(range(n), repeat=n))
        assert len(brute) == len(counts)
        for row, p in zip(counts, probs):
            assert p == pytest.approx(brute[tuple(row)] / n**n, rel=1e-12)


def brute_force_interval(statistic, *arrays, level=0.95):
    """Every ordered resample of every array (n^n each), equally weighted, inverted-CDF quantiles."""
    import itertools

    draws = [list(itertools.product(range(len(a)), repeat=len(a))) for a in arrays]
    values = np.sort(
        [statistic(*(np.asarray(a)[list(d)] for a, d in zip(arrays, ds))) for ds in itertools.product(*draws)]
    )
    cdf = np.arange(1, len(values) + 1) / len(values)
    return tuple(float(values[np.searchsorted(cdf, q - 1e-12)]) for q in ((1 - level) / 2, (1 + level) / 2))


def test_exact_bootstrap_intervals_equal_a_brute_force_enumeration_and_ignore_the_seed():
    x, y = np.array([66.0, 70.5, 61.0, 68.0]), np.array([62.0, 71.0, 60.5, 66.0])
    for statistic, arrays in ((stats.iqm, (x,)), (stats.probability_of_improvement, (y, x)), (np.mean, (x,))):
        point, low, high = stats.stratified_bootstrap_ci(statistic, *arrays, seed=1)
        assert (low, high) == pytest.approx(brute_force_interval(statistic, *arrays), abs=1e-12)
        assert stats.stratified_bootstrap_ci(statistic, *arrays, seed=2) == (point, low, high)
    # Five seeds: the IQM's 126 and P(B > A)'s 126^2 resamples, enumerated (fast path = generic).
    x5, y5 = np.array([66.0, 70.0, 61.0, 68.0, 64.0]), np.array([62.0, 71.0, 60.0, 66.0, 65.0])
    assert stats.stratified_bootstrap_ci(stats.iqm, x5) == stats.stratified_bootstrap_ci(lambda a: stats.iqm(a), x5)
    assert stats.stratified_bootstrap_ci(stats.probability_of_improvement, y5, x5) == stats.stratified_bootstrap_ci(
        lambda a, b: stats.probability_of_improvement(a, b), y5, x5
    )


def test_monte_carlo_beyond_the_exact_limit_is_close_to_the_exact_interval(monkeypatch):
    x5 = np.array([66.0, 70.0, 61.0, 68.0, 64.0])
    exact = stats.stratified_bootstrap_ci(stats.iqm, x5)
    monkeypatch.setattr(stats, "EXACT_LIMIT", 0)
    sampled = stats.stratified_bootstrap_ci(stats.iqm, x5, reps=10)  # at least MIN_MONTE_CARLO all the same
    assert sampled[0] == exact[0] and sampled[1:] == pytest.approx(exact[1:], abs=0.5)


def test_share_closed_is_a_paired_ratio_with_an_exact_bootstrap_and_refuses_an_unresolved_ceiling():
    import itertools

    ceiling = np.array([10.0, 12.0, 8.0, 11.0, 9.0])
    gap = np.array([2.0, 5.0, 1.0, 3.0, 4.0])
    out = stats.share_closed(gap, ceiling)
    assert out["resolved"] and out["share"] == pytest.approx(15 / 50)
    ratios = sorted(gap[list(d)].sum() / ceiling[list(d)].sum() for d in itertools.product(range(5), repeat=5))
    cdf = np.arange(1, len(ratios) + 1) / len(ratios)
    expected = [ratios[np.searchsorted(cdf, q - 1e-12)] for q in (0.025, 0.975)]
    assert [out["share_low"], out["share_high"]] == pytest.approx(expected, abs=1e-12)
    unresolved = stats.share_closed(gap, np.array([3.0, -2.0, 1.0, -1.0, 0.5]))
    assert not unresolved["resolved"] and "share" not in unresolved
    assert unresolved["ceiling_low"] < 0 < unresolved["ceiling_high"]
    with pytest.raises(ValueError, match="one value per seed"):
        stats.share_closed([1.0], [2.0])
