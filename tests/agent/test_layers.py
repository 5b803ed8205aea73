"""foresit_jax.layers against flax's own `nn.Dense` on the same parameters: `Dense` is
`nn.Dense` on a flattened input, `GridDense` is `nn.Dense` of the tiled concatenation.
Values and gradients (input and parameters) are compared; the parameter trees (names,
shapes, initial values) must be identical, so checkpoints written before these layers
existed still load."""

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from foresit_jax.layers import Dense, GridDense


def assert_trees_close(a, b, tol=1e-5):
    chex.assert_trees_all_equal_structs(a, b)
    jax.tree.map(lambda x, y: np.testing.assert_allclose(x, y, rtol=tol, atol=tol), a, b)


@pytest.mark.parametrize("shape", [(5,), (4, 5), (2, 3, 5), (2, 3, 4, 5)])
def test_dense_equals_flax_dense_in_value_and_gradient(shape):
    x = jax.random.normal(jax.random.PRNGKey(0), shape)
    ours, theirs = Dense(3), nn.Dense(3)
    params = ours.init(jax.random.PRNGKey(1), x)
    reference_params = theirs.init(jax.random.PRNGKey(1), x)
    chex.assert_trees_all_equal(params, reference_params)  # same names, shapes, initial values
    params = jax.tree.map(lambda p: p + 0.5, params)  # a non-zero bias

    def loss(module):
        return lambda p, x: jnp.sum(jnp.sin(module.apply(p, x)))

    assert ours.apply(params, x).shape == shape[:-1] + (3,)
    np.testing.assert_allclose(ours.apply(params, x), theirs.apply(params, x), rtol=1e-6, atol=1e-6)
    assert_trees_close(
        jax.grad(loss(ours), argnums=(0, 1))(params, x), jax.grad(loss(theirs), argnums=(0, 1))(params, x)
    )


def tiled_reference(grid, *vectors):
    """[grid : tile(v_1) : ...] along the channels, built explicitly."""
    tiles = [jnp.broadcast_to(v[..., None, None, :], grid.shape[:-1] + v.shape[-1:]) for v in vectors]
    return jnp.concatenate([grid, *tiles], axis=-1)


@pytest.mark.parametrize("batch", [(), (3,), (2, 3)])
def test_grid_dense_equals_flax_dense_of_the_tiled_input(batch):
    keys = jax.random.split(jax.random.PRNGKey(0), 4)
    grid = jax.random.normal(keys[0], batch + (3, 4, 6))
    goal = jax.random.normal(keys[1], batch + (5,))
    action = jax.random.normal(keys[2], batch + (2,))
    ours, theirs = GridDense(7), nn.Dense(7)
    params = ours.init(keys[3], grid, goal, action)
    reference_params = theirs.init(keys[3], tiled_reference(grid, goal, action))
    chex.assert_trees_all_equal(params, reference_params)  # kernel [6 + 5 + 2, 7], bias [7]
    params = jax.tree.map(lambda p: p + 0.25, params)

    def ours_loss(p, grid, goal, action):
        return jnp.sum(jnp.sin(ours.apply(p, grid, goal, action)))

    def theirs_loss(p, grid, goal, action):
        return jnp.sum(jnp.sin(theirs.apply(p, tiled_reference(grid, goal, action))))

    out = ours.apply(params, grid, goal, action)
    assert out.shape == batch + (3, 4, 7)
    np.testing.assert_allclose(out, theirs.apply(params, tiled_reference(grid, goal, action)), rtol=1e-5, atol=1e-5)
    args = (params, grid, goal, action)
    assert_trees_close(
        jax.grad(ours_loss, argnums=(0, 1, 2, 3))(*args), jax.grad(theirs_loss, argnums=(0, 1, 2, 3))(*args), 1e-4
    )


def test_grid_dense_without_vectors_is_a_dense_over_the_grid():
    grid = jax.random.normal(jax.random.PRNGKey(0), (2, 3, 4, 6))
    params = GridDense(5).init(jax.random.PRNGKey(1), grid)
    np.testing.assert_allclose(GridDense(5).apply(params, grid), nn.Dense(5).apply(params, grid), rtol=1e-6, atol=1e-6)


def test_grid_dense_rejects_vectors_of_another_batch():
    grid = jnp.zeros((2, 3, 4, 6))
    with pytest.raises(AssertionError):
        GridDense(5).init(jax.random.PRNGKey(0), grid, jnp.zeros((3, 5)))
