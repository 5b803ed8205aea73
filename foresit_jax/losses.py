"""Deprecated: the losses' old home, kept for one release (0.3.0).

The learner is one file now: return/advantage estimation and the A3C objective (Eq. 5,
Eq. 8-9) are in `foresit_jax.train`, beside the update that uses them, and f_w's
smooth-L1 is `foresit_jax.imagination.smooth_l1`. This module re-exports them and warns.
CHANGELOG.md says what moved where.
"""

from __future__ import annotations

import warnings

import importlib
import warnings

# name -> the module that holds it now; looked up on use (PEP 562), so this shim sits on no
# import floor above the ground (tests/test_structure.py)
_MOVED = {name: "foresit_jax.train" for name in (
    "a3c_loss", "advantages_and_returns", "discounted_returns", "episode_discounts", "explained_variance",
    "generalized_advantage_estimation", "masked_mean", "masked_variance",
)}  # fmt: skip
_MOVED["smooth_l1"] = "foresit_jax.imagination"

warnings.warn(
    "foresit_jax.losses is deprecated and goes in 0.3: the losses are in foresit_jax.train, smooth_l1 in "
    "foresit_jax.imagination",
    FutureWarning,
    stacklevel=2,
)


def __getattr__(name: str):
    if name in _MOVED:
        return getattr(importlib.import_module(_MOVED[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_MOVED))
