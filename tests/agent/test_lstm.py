"""foresit_jax.lstm: the split LSTM cell against flax's own `nn.OptimizedLSTMCell` on the
same parameters (a flax upgrade that renames or reorders its gates fails here), the
transposed-kernel product's gradient against plain autodiff, and the low-rank kernel
update against dense kernels."""

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from foresit_jax import lstm
from foresit_jax.networks import ActorCritic

F, H, B, T = 7, 5, 3, 4


def flax_cell_params(key):
    cell = nn.OptimizedLSTMCell(H)
    carry = lstm.initial_carry((B,), H)
    return cell, cell.init(key, carry, jnp.zeros((B, F)))["params"]


def test_parameter_names_are_flax_gates():
    _, params = flax_cell_params(jax.random.PRNGKey(0))
    assert set(params) == {"i" + g for g in lstm.LSTM_GATES} | {"h" + g for g in lstm.LSTM_GATES}
    kernels = lstm.lstm_kernels(params)
    chex.assert_shape(kernels.input_kernel, (F, 4 * H))
    chex.assert_shape(kernels.recurrent_kernel, (H, 4 * H))
    chex.assert_shape(kernels.bias, (4 * H,))


def test_split_step_equals_flax_cell_over_several_steps():
    cell, params = flax_cell_params(jax.random.PRNGKey(0))
    # Non-zero biases, so that a gate order mix-up cannot hide behind zeros.
    params = jax.tree.map(lambda x: x + 0.3 * jax.random.normal(jax.random.PRNGKey(3), x.shape), params)
    xs = jax.random.normal(jax.random.PRNGKey(1), (T, B, F))
    kernels = lstm.lstm_kernels(params)
    for transposed in (False, True):
        k = lstm.with_transposed_recurrent_kernel(kernels) if transposed else kernels
        ours = theirs = lstm.initial_carry((B,), H)
        for t in range(T):
            theirs, h_theirs = cell.apply({"params": params}, theirs, xs[t])
            ours, h_ours = lstm.lstm_step(k, ours, lstm.lstm_input_gates(k, xs[t]))
            np.testing.assert_allclose(h_ours, h_theirs, rtol=1e-6, atol=1e-6)
            jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-6), ours, theirs)


def test_the_encoder_lstm_is_the_flax_cell_and_its_unroll_restarts_episodes():
    """`EncoderLSTM` creates flax's parameters (a checkpoint of either reads in the other)
    and computes the cell; its `unroll` over input gates equals stepping flax's cell with
    the carry zeroed where an episode starts."""
    cell, params = flax_cell_params(jax.random.PRNGKey(5))
    ours = lstm.EncoderLSTM(H)
    carry0 = (jax.random.normal(jax.random.PRNGKey(6), (B, H)), jax.random.normal(jax.random.PRNGKey(7), (B, H)))
    mine = ours.init(jax.random.PRNGKey(5), carry0, jnp.zeros((B, F)))["params"]
    chex.assert_trees_all_equal(mine, params)
    params = jax.tree.map(lambda x: x + 0.3 * jax.random.normal(jax.random.PRNGKey(8), x.shape), params)
    xs = jax.random.normal(jax.random.PRNGKey(9), (T, B, F))
    episode_step = jnp.array([[3, 0, 1], [4, 1, 0], [0, 2, 1], [1, 0, 2]])  # [T, B]: 0 starts an episode

    def unroll(p):
        kernels = ours.apply({"params": p}, method=lstm.EncoderLSTM.kernels)
        gates = ours.apply({"params": p}, xs, kernels, method=lstm.EncoderLSTM.input_gates)
        return ours.apply({"params": p}, kernels, carry0, gates, episode_step == 0, method=lstm.EncoderLSTM.unroll)

    last, states = jax.jit(unroll)(params)
    theirs = carry0
    for t in range(T):
        theirs = lstm.reset_carry(episode_step[t] == 0, theirs)
        theirs, h = cell.apply({"params": params}, theirs, xs[t])
        np.testing.assert_allclose(states[t], h, rtol=1e-6, atol=1e-6)
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-6), last, theirs)


def test_split_step_gradient_equals_flax_cell_gradient():
    cell, params = flax_cell_params(jax.random.PRNGKey(2))
    xs = jax.random.normal(jax.random.PRNGKey(4), (T, B, F))

    def unroll_flax(p):
        carry = lstm.initial_carry((B,), H)
        total = 0.0
        for t in range(T):
            carry, h = cell.apply({"params": p}, carry, xs[t])
            total += jnp.sum(h * (t + 1))
        return total

    def unroll_split(p):
        k = lstm.with_transposed_recurrent_kernel(lstm.lstm_kernels(p))
        carry = lstm.initial_carry((B,), H)
        total = 0.0
        for t in range(T):
            carry, h = lstm.lstm_step(k, carry, lstm.lstm_input_gates(k, xs[t]))
            total += jnp.sum(h * (t + 1))
        return total

    g_flax, g_split = jax.grad(unroll_flax)(params), jax.grad(unroll_split)(params)
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6), g_split, g_flax)


def test_dot_with_transposed_kernel_gradient_is_the_plain_one():
    x = jax.random.normal(jax.random.PRNGKey(0), (B, H))
    w = jax.random.normal(jax.random.PRNGKey(1), (H, 4 * H))
    g = jax.random.normal(jax.random.PRNGKey(2), (B, 4 * H))
    plain = jax.grad(lambda x, w: jnp.vdot(g, jnp.dot(x, w)), argnums=(0, 1))(x, w)
    fast = jax.grad(
        lambda x, w: jnp.vdot(g, lstm.dot_with_transposed_kernel(x, w, lstm.materialized_transpose(w))), argnums=(0, 1)
    )(x, w)
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-6), fast, plain)


def test_reset_carry_zeroes_only_done_lanes():
    carry = (jnp.ones((3, H)), 2 * jnp.ones((3, H)))
    c, h = lstm.reset_carry(jnp.array([True, False, True]), carry)
    np.testing.assert_array_equal(c[:, 0], [0, 1, 0])
    np.testing.assert_array_equal(h[:, 0], [0, 2, 0])


def test_lstm_params_inverts_lstm_kernels():
    _, params = flax_cell_params(jax.random.PRNGKey(5))
    params = jax.tree.map(lambda x: x + jax.random.normal(jax.random.PRNGKey(6), x.shape), params)
    back = lstm.lstm_params(lstm.lstm_kernels(params))
    assert jax.tree.structure(back) == jax.tree.structure(params)
    jax.tree.map(np.testing.assert_array_equal, back, params)


def test_low_rank_update_equals_the_dense_kernels_in_numpy():
    """`dense()` adds a rank-R update into the kernels as numpy float64 does (W + rows^T
    deltas); a cell with the update acts as flax's cell with those kernels, over several
    steps; and the kernels' gradient over a few steps is the update whose deltas are the
    gradients of the pre-activations (the identity the maml inner loop rests on)."""
    cell, params = flax_cell_params(jax.random.PRNGKey(7))
    params = jax.tree.map(lambda x: x + 0.3 * jax.random.normal(jax.random.PRNGKey(8), x.shape), params)
    kernels = lstm.lstm_kernels(params)
    rank = 3
    ks = jax.random.split(jax.random.PRNGKey(9), 4)
    update = lstm.LowRankUpdate(
        jax.random.normal(ks[0], (rank, F)),
        jax.random.normal(ks[1], (rank, H)),
        0.2 * jax.random.normal(ks[2], (rank, 4 * H)),
    )
    updated = kernels._replace(update=update)
    dense = updated.dense()
    u = jax.tree.map(lambda x: np.asarray(x, np.float64), update)
    w_in = np.asarray(kernels.input_kernel, np.float64) + u.inputs.T @ u.deltas
    w_h = np.asarray(kernels.recurrent_kernel, np.float64) + u.hiddens.T @ u.deltas
    np.testing.assert_allclose(dense.input_kernel, w_in, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(dense.recurrent_kernel, w_h, rtol=1e-5, atol=1e-5)
    assert dense.update is None
    # Stacking two updates adds them.
    both = update.concat(update)
    twice = kernels._replace(update=both).dense()
    np.testing.assert_allclose(twice.input_kernel, w_in + u.inputs.T @ u.deltas, rtol=1e-5, atol=1e-5)

    xs = jax.random.normal(ks[3], (T, B, F))
    ours = theirs = lstm.initial_carry((B,), H)
    for t in range(T):
        ours, h_ours = lstm.lstm_step(updated, ours, lstm.lstm_input_gates(updated, xs[t]))
        theirs, h_theirs = cell.apply({"params": lstm.lstm_params(dense)}, theirs, xs[t])
        np.testing.assert_allclose(h_ours, h_theirs, rtol=1e-5, atol=1e-5)

    # The gradient of a loss over a few steps with respect to both kernels is
    # sum_t x_t^T delta_t and sum_t h_{t-1}^T delta_t, delta_t the gradient with respect to
    # a zero offset added to step t's pre-activations.
    def unroll(k, offsets):
        carry, hs, prevs = lstm.initial_carry((B,), H), [], []
        for t in range(T):
            prevs.append(carry[1])
            carry, h = lstm.lstm_step(k, carry, lstm.lstm_input_gates(k, xs[t]) + offsets[t])
            hs.append(h)
        return jnp.sum(jnp.stack(hs) ** 3), jnp.stack(prevs)

    offsets = jnp.zeros((T, B, 4 * H))
    grads, deltas = jax.grad(lambda k, o: unroll(k, o)[0], argnums=(0, 1))(kernels, offsets)
    prevs = unroll(kernels, offsets)[1]  # h_{t-1} [T, B, H]
    np.testing.assert_allclose(grads.input_kernel, jnp.einsum("tbf,tbg->fg", xs, deltas), rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(grads.recurrent_kernel, jnp.einsum("tbh,tbg->hg", prevs, deltas), rtol=1e-4, atol=1e-5)


@pytest.fixture(scope="module")
def small_agent():
    """(the Networks of an a3c agent of hidden size H, its initial parameters)."""
    from foresit_jax.config import Config
    from foresit_jax.networks import build

    nets = build(Config(method="a3c", hidden_size=H, attention_size=4, value_hidden=4, imagination_layer_sizes=(4, H)))
    params, _ = nets.init(jax.random.key(0), {"view": jnp.zeros((3, 2, 23)), "target": jnp.ones((300,))})
    return nets, params


def kernels_of(nets, params, update=None):
    """The encoder LSTM's kernels under `params` (`ActorCritic.lstm_kernels`)."""
    return nets.model.apply(params, update, method=ActorCritic.lstm_kernels)


def test_the_agents_lstm_kernels_come_from_its_encoder_cell(small_agent):
    """`ActorCritic.lstm_kernels` (the network's own method) gives the kernels of the encoder's
    cell, the ones at the parameter path MAML splits by, and they run the cell exactly."""
    nets, params = small_agent
    mine = kernels_of(nets, params)
    chex.assert_trees_all_equal(mine, lstm.lstm_kernels(lstm.encoder_lstm_params(params)))
    cell = nn.OptimizedLSTMCell(H)
    x = jax.random.normal(jax.random.key(1), (B, 3 * 2 * 64))
    carry = (jax.random.normal(jax.random.key(2), (B, H)), jax.random.normal(jax.random.key(3), (B, H)))
    (c, h), out = cell.apply({"params": lstm.encoder_lstm_params(params)}, carry, x)
    (c2, h2), out2 = lstm.lstm_step(mine, carry, lstm.lstm_input_gates(mine, x))
    np.testing.assert_allclose(out2, out, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(c2, c, rtol=1e-6, atol=1e-6)


def test_splitting_the_agents_tree_at_the_encoder_lstm_and_replacing_its_kernels(small_agent):
    """What the maml base does with the tree: the split holds exactly the cell's eight
    kernels, joins back to the same tree, and replacing the kernels by updated ones changes
    those eight leaves alone, to the dense kernels' values."""
    nets, params = small_agent
    kernels, rest = lstm.split_encoder_lstm_kernels(params)
    cell = lstm.encoder_lstm_params(kernels)
    assert {name: set(leaves) for name, leaves in cell.items()} == {
        n + g: {"kernel"} for n in "ih" for g in lstm.LSTM_GATES
    }
    assert all("kernel" not in leaves for leaves in lstm.encoder_lstm_params(rest).values())
    chex.assert_trees_all_equal(lstm.join_partial_trees(kernels, rest), params)

    keys = jax.random.split(jax.random.key(4), 3)
    update = lstm.LowRankUpdate(*(jax.random.normal(k, s) for k, s in zip(keys, [(2, 3 * 2 * 64), (2, H), (2, 4 * H)])))
    changed = lstm.with_encoder_lstm_kernels(params, kernels_of(nets, params)._replace(update=update))
    dense = kernels_of(nets, params)._replace(update=update).dense()
    chex.assert_trees_all_close(
        kernels_of(nets, changed), dense._replace(recurrent_kernel_t=None), rtol=1e-6, atol=1e-6
    )
    flat_old, flat_new = (jax.tree_util.tree_flatten_with_path(t)[0] for t in (params, changed))
    moved = [jax.tree_util.keystr(p) for (p, a), (_, b) in zip(flat_old, flat_new) if not np.array_equal(a, b)]
    assert len(moved) == 8 and all("'lstm'" in p and "'kernel'" in p for p in moved)
