"""Model selection on the validation split: one protocol for `train` and `sweep`.

After each chunk of updates the agent is evaluated on `val_episodes_per_room` validation
episodes per room type, the same episodes (and the same action-sampling draws) after every
chunk: two checkpoints' validation SRs then differ by what the models do, not by which
episodes were drawn (common random numbers; drawing new episodes each time added a noise of
about 4.6 SR points at quick's 4 x 25 episodes to every comparison, and the model so selected
tested 0.8 [0.0, 1.5] SR points below the last one over 18 quick runs: see docs/evaluation.md).
The model with the highest validation SR so far is kept, the later one on ties (at these
budgets training is still improving: a tie is no evidence against the later model), and is
the one evaluated on the test split at the end.  The keys are functions of the run's seed
only, so seed i of a sweep validates and tests on the very episodes `train --seed i` does.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax

from experiments.errors import UserError

# Bumped whenever what selects a run's model changes (the keys, the tie rule, the presets'
# validation episodes): results of another version are not combined with this one's
# (`sweep --reuse`), nor continued by it (`--resume`: `check_resumable`). 1 (unrecorded): new validation episodes after every chunk, the first
# model on ties, 25 episodes per room type at quick.
PROTOCOL_VERSION = 2
TEST_SEED_OFFSET = 10_000
VALIDATION_SEED_OFFSET = 20_000


def check_resumable(recorded: int | None, what: str) -> None:
    """Refuse (one line) to continue a run whose validations so far were made under another
    protocol: its checkpoints would be compared on other episodes (and by another tie rule)
    than the rest. `recorded` None: the run predates the record (made before protocol 2 was
    written into run.json and progress.json; it cannot be told apart and is let through)."""
    if recorded is not None and recorded != PROTOCOL_VERSION:
        raise UserError(
            f"{what} was validated under selection protocol {recorded}, this code's is {PROTOCOL_VERSION} "
            "(experiments/running/selection.py): finish it with the code that started it, or start it again"
        )


def run_key(seed: int) -> jax.Array:
    """The key a run of `seed` initialises its training state from."""
    return jax.random.PRNGKey(seed)


def validation_key(seed: int) -> jax.Array:
    """The key of every validation of the run of `seed` (the same episodes after each chunk)."""
    return jax.random.PRNGKey(seed + VALIDATION_SEED_OFFSET)


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
        """Keep (update, params) if their validation SR is at least the best so far (offers
        come in training order: the later model wins a tie); True if kept."""
        if sr >= self.sr:
            self.sr, self.update, self.params = float(sr), int(update), params
            return True
        return False


def validate(evaluator, params, config, seed: int, episodes_per_room: int) -> dict:
    """The validation of a model of the run of `seed` (`Evaluator.evaluate`)."""
    return evaluator.evaluate(params, config, "val", validation_key(seed), episodes_per_room)
