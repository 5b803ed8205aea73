"""The navigation metrics of Section 5, defined once (envs, foresit_jax and experiments use these).

SPL_i = s_i * L^g_i / max(L_i, L^g_i), where L^g is the oracle's shortest number of actions
to success (Done counted) and L the number of actions taken; the L >= 5 bucket of Table 1
holds the episodes with L^g >= `LONG_PATH_MIN`.  Houses (``layout="house"``), whose paths
are about 3x longer, add the L >= 10 and L >= 20 buckets (`LONG_PATH_MINS`) and buckets of
L^g up to 40+ (`LENGTH_BUCKETS_OF`).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

LONG_PATH_MIN = 5  # Table 1's "L >= 5" bucket: episodes whose L^g is at least this
# Buckets of L^g (first, last; None: no upper end) for SR/SPL by optimal path length: the
# paper's claim that foresight helps most on long paths, looked at finer than L >= 5. The
# edges keep every bucket populated at the test split's lengths (mean L^g 4.5 to 11.8 by
# room type, see experiments.demo) and put LONG_PATH_MIN on an edge.
LENGTH_BUCKETS = ((1, 2), (3, 4), (5, 6), (7, 9), (10, 14), (15, None))
# Houses: median L^g 19 on the test houses, 95th percentile 46.
HOUSE_LENGTH_BUCKETS = ((1, 4), (5, 9), (10, 14), (15, 19), (20, 29), (30, 39), (40, None))
LENGTH_BUCKETS_OF = {"room": LENGTH_BUCKETS, "house": HOUSE_LENGTH_BUCKETS}
LONG_PATH_MINS = {"room": (LONG_PATH_MIN,), "house": (LONG_PATH_MIN, 10, 20)}  # the L >= m buckets


def spl(success, length, optimal_length):
    """Per-episode SPL term `s * L^g / max(L, L^g)` (float32, any shape; jnp or numpy in)."""
    success = jnp.asarray(success).astype(jnp.float32)
    optimal = jnp.asarray(optimal_length).astype(jnp.float32)
    return success * optimal / jnp.maximum(jnp.asarray(length).astype(jnp.float32), optimal)


def summarize(success, spl_terms, optimal_length, long_path_mins=(LONG_PATH_MIN,)) -> dict:
    """SR, SPL, SR>=m, SPL>=m (in %) for each m of `long_path_mins` (a layout's:
    `LONG_PATH_MINS`) and the episode counts, from per-episode arrays (host side).

    An empty L>=m bucket gives NaN for its two rates (write it as null in JSON)."""
    success = np.asarray(success, np.float64).reshape(-1)
    spl_terms = np.asarray(spl_terms, np.float64).reshape(-1)
    optimal = np.asarray(optimal_length).reshape(-1)

    def pct(x, mask):
        return float(100.0 * x[mask].mean()) if mask.any() else float("nan")

    every = np.ones(success.shape, bool)
    out = {"SR": pct(success, every), "SPL": pct(spl_terms, every)}
    for m in long_path_mins:
        out[f"SR>={m}"], out[f"SPL>={m}"] = pct(success, optimal >= m), pct(spl_terms, optimal >= m)
    out["episodes"] = int(success.shape[0])
    for m in long_path_mins:
        out[f"episodes>={m}"] = int((optimal >= m).sum())
    return out


def bucket_label(bucket) -> str:
    first, last = bucket
    return f"{first}+" if last is None else f"{first}-{last}"


def by_length(success, spl_terms, optimal_length, buckets=LENGTH_BUCKETS) -> dict:
    """{label ("1-2", ..., "15+"): {"SR", "SPL" (in %), "episodes"}} over the episodes whose
    L^g falls in each bucket of `buckets` (host side; an empty bucket's rates are NaN)."""
    success = np.asarray(success, np.float64).reshape(-1)
    spl_terms = np.asarray(spl_terms, np.float64).reshape(-1)
    optimal = np.asarray(optimal_length).reshape(-1)
    out = {}
    for first, last in buckets:
        mask = (optimal >= first) & (optimal <= (np.inf if last is None else last))
        rate = (lambda x: float(100.0 * x[mask].mean())) if mask.any() else (lambda x: float("nan"))
        out[bucket_label((first, last))] = {"SR": rate(success), "SPL": rate(spl_terms), "episodes": int(mask.sum())}
    return out
