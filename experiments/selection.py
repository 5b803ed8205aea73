"""Model selection on the validation split: one protocol for `train` and `sweep`.

After each chunk of updates the agent is evaluated on `val_episodes_per_room` validation
episodes per room type; the model with the highest validation SR so far is kept (the
first one on ties) and is the one evaluated on the test split at the end.  The keys are
functions of the run's seed only, so seed i of a sweep validates and tests on the very
episodes `train --seed i` does.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax

TEST_SEED_OFFSET = 10_000


def run_key(seed: int) -> jax.Array:
    """The key a run of `seed` initialises its training state from."""
    return jax.random.PRNGKey(seed)


def validation_key(seed: int, update: int) -> jax.Array:
    """The key of the validation after `update` updates of the run of `seed`."""
    return jax.random.fold_in(jax.random.PRNGKey(seed), update)


def test_key(seed: int) -> jax.Array:
    """The key of the final test evaluation (and of the random policy beside it)."""
    return jax.random.PRNGKey(seed + TEST_SEED_OFFSET)


@dataclasses.dataclass
class Selection:
    """The best model so far of one run: its validation SR, its update, and (in a sweep,
    which keeps them in memory) its parameters."""

    sr: float = -1.0
    update: int | None = None
    params: Any = None

    def offer(self, sr: float, update: int, params: Any = None) -> bool:
        """Keep (update, params) if their validation SR beats the best so far; True if kept."""
        if sr > self.sr:
            self.sr, self.update, self.params = float(sr), int(update), params
            return True
        return False


def validate(evaluator, params, config, seed: int, update: int, episodes_per_room: int) -> dict:
    """The validation of the run of `seed` after `update` updates (`Evaluator.evaluate`)."""
    return evaluator.evaluate(params, config, "val", validation_key(seed, update), episodes_per_room)
