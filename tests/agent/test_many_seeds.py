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
        method="a3c+foresit",
        num_lanes=2,
        num_updates=2,
        room_types=("bathroom",),
        hidden_size=16,
        attention_size=16,
        value_hidden=16,
        imagination_layer_sizes=(16, 8, 4, 8, 16, 16),
        buffer_size=1,
        imagination_epochs=1,
    )
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


# The README's library snippet at its own sizes, in a subprocess with a deadline: on jax
# 0.10.2 it hung for good (both XLA:CPU pool threads blocked in batched LAPACK QRs of the
# orthogonal initialisers, vmapped over the seeds; foresit_jax.layers.orthogonal). .ci/run
# runs it again on the unconstrained resolution of Python 3.11, where pip picks jax 0.10.2.
SNIPPET = """
import jax
from foresit_jax.config import Config
from foresit_jax.train import make_train
train = make_train(Config(method="a3c+foresit", num_lanes=16, num_updates=2))
state, metrics = jax.jit(jax.vmap(train))(jax.random.split(jax.random.PRNGKey(0), 2))
print("finished", jax.__version__, jax.block_until_ready(metrics["losses/total_loss"]).shape)
"""


@pytest.mark.slow
@pytest.mark.readme_snippet
def test_the_readme_snippet_finishes_at_its_own_sizes():
    import subprocess
    import sys

    try:
        out = subprocess.run([sys.executable, "-c", SNIPPET], capture_output=True, text=True, timeout=280)
    except subprocess.TimeoutExpired:
        pytest.fail(
            "the README's snippet (2 seeds vmapped with init, 16 lanes) did not finish in 280 s: the jax "
            f"{jax.__version__} CPU hang of docs/design.md's known hazard is back"
        )
    assert out.returncode == 0, out.stderr[-2000:]
    assert "finished" in out.stdout and out.stdout.strip().endswith("(2, 2)"), out.stdout


def test_the_orthogonal_initialiser_draws_each_seed_as_flax_does_unbatched():
    """layers.orthogonal: vmapped over keys (one QR at a time), each key's matrix is flax's
    own orthogonal draw from that key, bit for bit; unvmapped it is flax's."""
    import flax.linen as nn

    from foresit_jax.layers import orthogonal

    keys = jax.random.split(jax.random.PRNGKey(3), 3)
    mine = jax.jit(jax.vmap(lambda k: orthogonal(0.5)(k, (24, 6))))(keys)
    flax_batched = jax.jit(jax.vmap(lambda k: nn.initializers.orthogonal(0.5)(k, (24, 6))))(keys)
    np.testing.assert_array_equal(mine, flax_batched)  # the values of the batched QR of before
    one = jax.jit(lambda k: nn.initializers.orthogonal(0.5)(k, (24, 6)))
    for i, key in enumerate(keys):
        np.testing.assert_array_equal(mine[i], one(key))
    np.testing.assert_array_equal(orthogonal()(keys[0], (8, 8)), nn.initializers.orthogonal()(keys[0], (8, 8)))
    q = np.asarray(mine[0]) / 0.5
    np.testing.assert_allclose(q.T @ q, np.eye(6), atol=1e-5)
    text = jax.jit(jax.vmap(lambda k: orthogonal()(k, (16, 16)))).lower(keys).as_text()
    assert "while" in text  # the batch is a loop of unbatched draws


def test_the_orthogonal_initialiser_vmapped_eagerly_draws_flax_compiled_values():
    """Eagerly vmapped, as experiments.sweep initialises its seeds, layers.orthogonal gives
    each key flax's compiled draw at the actor's shape and scale (128 x 6, 0.01): `lax.map`
    runs the draw compiled. (flax's eager draw at this shape differs from it in
    the last bit: docs/design.md, "A known hazard".)"""
    import flax.linen as nn

    from foresit_jax.layers import orthogonal

    keys = jax.random.split(jax.random.PRNGKey(3), 5)
    eager = np.asarray(jax.vmap(lambda k: orthogonal(0.01)(k, (128, 6)))(keys))
    compiled = jax.jit(lambda k: nn.initializers.orthogonal(0.01)(k, (128, 6)))
    for i, key in enumerate(keys):
        np.testing.assert_array_equal(eager[i], compiled(key))
    q = eager[0] / 0.01
    np.testing.assert_allclose(q.T @ q, np.eye(6), atol=1e-5)
