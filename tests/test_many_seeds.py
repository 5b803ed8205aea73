"""A seed sweep with many seeds in one program finishes (docs/design.md's known hazard: a
16-seed vmapped loop was seen to hang on jax 0.10.2's CPU backend), and the seeds differ."""

import jax
import numpy as np
import pytest

from foresit_jax.config import Config
from foresit_jax.train import make_trainer


@pytest.mark.slow
@pytest.mark.timeout(240)
def test_sixteen_seeds_vmapped_in_one_jit_finish_and_differ():
    config = Config(
        method="a3c+foresit", num_lanes=2, num_updates=2, room_types=("bathroom",), hidden_size=16,
        attention_size=16, value_hidden=16, imagination_layer_sizes=(16, 8, 4, 8, 16, 16), buffer_size=1,
        imagination_epochs=1,
    )  # fmt: skip
    trainer = make_trainer(config)
    keys = jax.random.split(jax.random.PRNGKey(0), 16)
    states, metrics = jax.jit(jax.vmap(trainer.train))(keys)
    loss = np.asarray(metrics["losses/total_loss"])
    assert loss.shape == (16, 2)
    assert np.isfinite(loss).all()
    assert np.asarray(states.update).tolist() == [2] * 16
    # Different seeds give different parameters (the vmap did not collapse the seeds).
    kernel = np.asarray(jax.tree.leaves(states.params)[0])
    assert len({kernel[i].tobytes() for i in range(16)}) == 16
