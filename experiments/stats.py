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
