"""The navigation metrics of Section 5, defined once (envs, foresit_jax and experiments use these).

SPL_i = s_i * L^g_i / max(L_i, L^g_i), where L^g is the oracle's shortest number of actions
to success (Done counted) and L the number of actions taken; the L >= 5 bucket of Table 1
holds the episodes with L^g >= `LONG_PATH_MIN`.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

LONG_PATH_MIN = 5  # Table 1's "L >= 5" bucket: episodes whose L^g is at least this


def spl(success, length, optimal_length):
    """Per-episode SPL term `s * L^g / max(L, L^g)` (float32, any shape; jnp or numpy in)."""
    success = jnp.asarray(success).astype(jnp.float32)
    optimal = jnp.asarray(optimal_length).astype(jnp.float32)
    return success * optimal / jnp.maximum(jnp.asarray(length).astype(jnp.float32), optimal)


def summarize(success, spl_terms, optimal_length) -> dict:
    """SR, SPL, SR>=5, SPL>=5 (in %) and episode counts from per-episode arrays (host side).

    An empty L>=5 bucket gives NaN for its two rates (write it as null in JSON)."""
    success = np.asarray(success, np.float64).reshape(-1)
    spl_terms = np.asarray(spl_terms, np.float64).reshape(-1)
    long = np.asarray(optimal_length).reshape(-1) >= LONG_PATH_MIN
    every = np.ones_like(long)

    def pct(x, mask):
        return float(100.0 * x[mask].mean()) if mask.any() else float("nan")

    return {
        "SR": pct(success, every),
        "SPL": pct(spl_terms, every),
        "SR>=5": pct(success, long),
        "SPL>=5": pct(spl_terms, long),
        "episodes": int(success.shape[0]),
        "episodes>=5": int(long.sum()),
    }
