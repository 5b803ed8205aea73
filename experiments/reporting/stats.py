"""Statistics over seeds: mean, sample std and a Student-t 95% confidence interval, and
the paired comparison of two methods run with the same seeds on the same episodes.

Seeds are few (3-5), so intervals use the t distribution with n - 1 degrees of freedom,
not the normal one; with one seed the spread is unknown and reported as NaN (written as
null in JSON), never as 0.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats as _stats

LEVEL = 0.95


def summary(values, level: float = LEVEL) -> dict[str, float]:
    """{"n", "mean", "std" (sample, ddof 1), "ci_low", "ci_high"} of the finite values
    (NaN, e.g. an empty L>=5 bucket, is left out)."""
    x = np.asarray([v for v in np.asarray(values, float).ravel() if np.isfinite(v)])
    n = len(x)
    if n == 0:
        return {"n": 0, "mean": math.nan, "std": math.nan, "ci_low": math.nan, "ci_high": math.nan}
    mean = float(x.mean())
    if n == 1:
        return {"n": 1, "mean": mean, "std": math.nan, "ci_low": math.nan, "ci_high": math.nan}
    std = float(x.std(ddof=1))
    half = float(_stats.t.ppf(0.5 + level / 2, n - 1)) * std / math.sqrt(n)
    return {"n": n, "mean": mean, "std": std, "ci_low": mean - half, "ci_high": mean + half}


def paired(a, b, level: float = LEVEL) -> dict[str, float]:
    """b - a over paired seeds (the same seed of both methods, the same test episodes):
    the mean difference, its confidence interval, and the two-sided paired t-test's p-value
    (NaN with fewer than two pairs, or when every difference is the same)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.shape != b.shape:
        raise ValueError(f"paired: one value per seed of each method, got {a.shape} and {b.shape}")
    d = summary(b - a, level)
    p = math.nan
    if d["n"] >= 2 and d["std"] > 0:
        t = d["mean"] / (d["std"] / math.sqrt(d["n"]))
        p = float(2 * _stats.t.sf(abs(t), d["n"] - 1))
    return {"n": d["n"], "diff": d["mean"], "ci_low": d["ci_low"], "ci_high": d["ci_high"], "p": p}


def verdict(pair: dict[str, float], claim_positive: bool = True) -> str:
    """'holds' when the interval of b - a lies above 0 (below, for a negative claim),
    'does not hold' when it lies on the other side, 'cannot tell at this budget' else
    (also when the differences have no spread, so that there is no interval)."""
    low, high = pair["ci_low"], pair["ci_high"]
    if not (math.isfinite(low) and math.isfinite(high)) or low == high:  # no spread: no interval
        return "cannot tell at this budget"
    if not claim_positive:
        low, high = -high, -low
    if low > 0:
        return "holds"
    if high < 0:
        return "does not hold"
    return "cannot tell at this budget"


# ------------------------------------------------------------------ robust statistics
# What five seeds can tell (docs/results.md): the interquartile mean and the probability of
# improvement with stratified-bootstrap intervals, as rliable defines them (Agarwal et al.,
# "Deep RL at the Edge of the Statistical Precipice", 2021; checked against rliable 1.2.0 in
# tests/experiments/test_robust_stats.py; rliable is not a dependency: it ships as an sdist only and
# needs arch < 8, pandas and seaborn, for the three functions re-derived here), Holm's correction over a declared family of comparisons, and
# the smallest effect a paired t-test over n seeds detects with a given power.
# Scores are [runs, tasks] arrays (a 1-D array is one task): runs are seeds, tasks are
# whatever is scored separately (room types, setups).


def _runs_by_tasks(scores) -> np.ndarray:
    x = np.asarray(scores, float)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] == 0:
        raise ValueError(f"scores must be [runs] or [runs, tasks] with at least one run, got shape {x.shape}")
    return x


def iqm(scores) -> float:
    """Interquartile mean: the mean of the middle 50% of all runs' scores pooled over tasks
    (scipy's trim_mean with 25% cut from each end, as rliable's aggregate_iqm)."""
    return float(_stats.trim_mean(_runs_by_tasks(scores), proportiontocut=0.25, axis=None))


def probability_of_improvement(x, y) -> float:
    """P(X > Y) + P(X = Y) / 2 for a run X of method x and a run Y of method y, each task
    on its own (the Mann-Whitney U statistic over all pairs of runs), averaged over tasks:
    rliable's probability_of_improvement. Unpaired: x and y may have different run counts."""
    x, y = _runs_by_tasks(x), _runs_by_tasks(y)
    if x.shape[1] != y.shape[1]:
        raise ValueError(f"x and y must score the same tasks, got {x.shape[1]} and {y.shape[1]}")
    per_task = [float(((a[:, None] > b[None, :]) + 0.5 * (a[:, None] == b[None, :])).mean()) for a, b in zip(x.T, y.T)]
    return float(np.mean(per_task))


# Up to this many distinct resamples, `stratified_bootstrap_ci` enumerates them exactly:
# 126 multisets for one method's 5 seeds, 92,378 for 10, 126^2 = 15,876 for a pair's 5 and 5.
EXACT_LIMIT = 100_000
# Beyond it, at least this many Monte Carlo resamples.
MIN_MONTE_CARLO = 20_000


def multisets(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Every multiset of size n drawn from n items, as counts `[K, n]` (K = C(2n - 1, n)),
    and its probability under n draws with replacement `[K]` (the multinomial
    n! / prod(c_i!) / n^n; they sum to 1)."""
    counts = []

    def fill(prefix, left, slots):
        if slots == 1:
            counts.append(prefix + [left])
            return
        for c in range(left, -1, -1):
            fill(prefix + [c], left - c, slots - 1)

    fill([], n, n)
    counts = np.asarray(counts, np.int64)
    log_p = math.lgamma(n + 1) - np.sum([[math.lgamma(c + 1) for c in row] for row in counts], axis=1) - n * math.log(n)
    return counts, np.exp(log_p)


def weighted_quantiles(values, weights, qs) -> list[float]:
    """The inverted-CDF quantiles of a discrete distribution: for each q, the smallest value
    v whose cumulative weight reaches q (numpy's `method="inverted_cdf"` for equal weights,
    Hyndman and Fan's definition 1). Both ends of an interval are attained values, so an
    interval never reports a value no resample gives."""
    order = np.argsort(values, kind="stable")
    v, cdf = np.asarray(values, float)[order], np.cumsum(np.asarray(weights, float)[order])
    cdf /= cdf[-1]
    return [float(v[min(np.searchsorted(cdf, q - 1e-12, side="left"), len(v) - 1)]) for q in qs]


def _exact_one_task(statistic, arrays, per_stratum):
    """(values, weights) of every resample for the two statistics the reports use on one
    task, without a Python loop over the resamples: the IQM of one array (each multiset's
    runs built at once) and P(X > Y) of two (C_x S C_y^T / (n_x n_y), S the pairwise win
    matrix); None for anything else (the generic enumeration then runs)."""
    if any(a.shape[1] != 1 for a in arrays):
        return None
    if statistic is iqm and len(arrays) == 1:
        (counts, probs), x = per_stratum[0], arrays[0][:, 0]
        runs = np.repeat(np.tile(x, len(counts)), counts.ravel()).reshape(len(counts), len(x))
        return _stats.trim_mean(runs, proportiontocut=0.25, axis=1), probs
    if statistic is probability_of_improvement and len(arrays) == 2:
        (cx, px), (cy, py) = per_stratum
        x, y = arrays[0][:, 0], arrays[1][:, 0]
        wins = (x[:, None] > y[None, :]) + 0.5 * (x[:, None] == y[None, :])
        values = cx @ wins @ cy.T / (len(x) * len(y))
        return values.ravel(), np.outer(px, py).ravel()
    return None


def stratified_bootstrap_ci(statistic, *scores, reps: int = MIN_MONTE_CARLO, level: float = LEVEL, seed: int = 0):
    """Percentile interval of `statistic(*scores)` under the stratified bootstrap: each
    array's runs are resampled with replacement within each task, the arrays independently
    (rliable's StratifiedBootstrap, and StratifiedIndependentBootstrap for several).
    Returns (point, low, high).

    Exact where cheap: when the distinct resamples (a multiset of runs per task and array)
    number at most `EXACT_LIMIT`, each is enumerated with its multinomial probability, so
    the interval does not move with a random seed (the statistic must not depend on the
    runs' order, as the IQM, the mean and P(B > A) do not). Otherwise `max(reps,
    MIN_MONTE_CARLO)` Monte Carlo resamples from `seed`. Either way the ends are the
    inverted-CDF quantiles (`weighted_quantiles`) at (1 - level) / 2 and (1 + level) / 2."""
    arrays = [_runs_by_tasks(s) for s in scores]
    point = float(statistic(*arrays))
    qs = ((1 - level) / 2, (1 + level) / 2)
    strata = [(i, t) for i, a in enumerate(arrays) for t in range(a.shape[1])]
    sizes = [math.comb(2 * arrays[i].shape[0] - 1, arrays[i].shape[0]) for i, _ in strata]
    if math.prod(sizes) <= EXACT_LIMIT:
        per_stratum = [multisets(arrays[i].shape[0]) for i, _ in strata]
        fast = _exact_one_task(statistic, arrays, per_stratum)
        if fast is not None:
            return (point, *weighted_quantiles(*fast, qs))
        values, weights = [], []
        for choice in np.ndindex(*sizes):
            resampled = [a.copy() for a in arrays]
            weight = 1.0
            for (i, t), k, (counts, probs) in zip(strata, choice, per_stratum):
                resampled[i][:, t] = np.repeat(arrays[i][:, t], counts[k])
                weight *= probs[k]
            values.append(statistic(*resampled))
            weights.append(weight)
        return (point, *weighted_quantiles(values, weights, qs))
    rng = np.random.default_rng(seed)
    values = np.empty(max(reps, MIN_MONTE_CARLO))
    for r in range(len(values)):
        resampled = []
        for a in arrays:
            rows = rng.integers(0, a.shape[0], size=a.shape)  # per task (column) its own draw
            resampled.append(np.take_along_axis(a, rows, axis=0))
        values[r] = statistic(*resampled)
    return (point, *weighted_quantiles(values, np.ones(len(values)), qs))


def holm(p_values) -> np.ndarray:
    """Holm's step-down adjusted p-values for a family of tests (NaN stays NaN and does not
    count towards the family's size): reject a hypothesis at level alpha when its adjusted
    p-value is at most alpha, with the family-wise error rate at most alpha."""
    p = np.asarray(p_values, float)
    adjusted = np.full(p.shape, math.nan)
    finite = np.flatnonzero(np.isfinite(p))
    m = len(finite)
    order = finite[np.argsort(p[finite], kind="stable")]
    running = 0.0
    for rank, index in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[index]))
        adjusted[index] = running
    return adjusted


def minimum_detectable_effect(sd_diff: float, n: int, level: float = LEVEL, power: float = 0.8) -> float:
    """The smallest true mean difference a two-sided paired t-test over n seeds (per-seed
    differences with standard deviation sd_diff) detects at `level` with probability
    `power`, solved exactly with the noncentral t distribution. NaN with fewer than two
    seeds or no spread."""
    if n < 2 or not math.isfinite(sd_diff) or sd_diff <= 0:
        return math.nan
    df = n - 1
    critical = float(_stats.t.ppf(0.5 + level / 2, df))

    def power_at(effect: float) -> float:
        nc = effect * math.sqrt(n) / sd_diff
        return float(_stats.nct.sf(critical, df, nc) + _stats.nct.cdf(-critical, df, nc))

    from scipy.optimize import brentq

    high = sd_diff
    while power_at(high) < power:
        high *= 2
    return float(brentq(lambda e: power_at(e) - power, 0.0, high, xtol=1e-10))


def share_closed(gap_closed, ceiling, level: float = LEVEL) -> dict:
    """The share of a ceiling an arm closes, mean(gap_closed) / mean(ceiling), over paired
    seeds (gap_closed[i] = B_i - A_i, ceiling[i] = C_i - A_i for the same seed i), with a
    paired bootstrap interval: the seeds resampled together (exact, every multiset with its
    multinomial weight, up to `EXACT_LIMIT`; else Monte Carlo), inverted-CDF quantiles.
    The share is defined only where the ceiling is resolved: its Student-t interval
    (`paired`) excludes 0; otherwise {"resolved": False} and no share (a ratio over a
    denominator that may be 0 has no interval)."""
    gap, top = np.asarray(gap_closed, float), np.asarray(ceiling, float)
    if gap.shape != top.shape or gap.ndim != 1 or len(gap) < 2:
        raise ValueError(f"share_closed: one value per seed of each, at least two, got {gap.shape} and {top.shape}")
    d = summary(top, level)
    resolved = bool(d["ci_low"] > 0 or d["ci_high"] < 0)
    out = {"resolved": resolved, "ceiling": d["mean"], "ceiling_low": d["ci_low"], "ceiling_high": d["ci_high"]}
    if not resolved:
        return out
    n = len(top)
    qs = ((1 - level) / 2, (1 + level) / 2)
    if math.comb(2 * n - 1, n) <= EXACT_LIMIT:
        counts, weights = multisets(n)
    else:
        counts = np.random.default_rng(0).multinomial(n, np.full(n, 1 / n), size=MIN_MONTE_CARLO)
        weights = np.ones(len(counts))
    ratios = (counts @ gap) / (counts @ top)
    low, high = weighted_quantiles(ratios, weights, qs)
    return {**out, "share": float(gap.mean() / top.mean()), "share_low": low, "share_high": high}
