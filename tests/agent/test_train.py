"""foresit_jax.train: the update (what each loss moves, tracing, determinism), every method,
the vmapped seed sweep, and learning on an easy setting.

Compiled functions are shared through `train_helpers` (one jitted update per config for
the whole session); see its docstring.
"""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import train_helpers as H
from foresit_jax import imagination
from foresit_jax import train as train_module
from foresit_jax.rollout import AgentParams
from foresit_jax.train import Trainer
from foresit_jax.networks import ActorCritic

FORESIT = H.tiny_config("a3c+foresit")


@pytest.fixture(scope="module")
def foresit_run():
    """Seed 0, 12 updates of the tiny ForeSIT config: (final state, metrics [12])."""
    return H.init_and_run(FORESIT, 0, 12)


# ---------------------------------------------------------------------- tracing, determinism
def test_update_keeps_the_state_types_so_chained_updates_never_retrace(foresit_run):
    trainer = H.trainer(FORESIT)
    init_shapes = jax.eval_shape(trainer.init, jax.random.PRNGKey(0))
    out_shapes, _ = jax.eval_shape(trainer.update, init_shapes, trainer.env_params)
    same = jax.tree.map(
        lambda a, b: (a.shape, a.dtype, a.weak_type) == (b.shape, b.dtype, b.weak_type), init_shapes, out_shapes
    )
    assert all(jax.tree.leaves(same)), same
    # The shared jitted update is wrapped in chex.assert_max_traces(n=1): twelve chained
    # calls (the fixture) and these, from another seed, compiled it once.
    state = H.jitted_init(FORESIT)(jax.random.PRNGKey(5))
    update = H.jitted_update(FORESIT)
    for _ in range(3):
        state, _ = update(state, trainer.env_params)
    assert int(state.update) == 3
    assert update._cache_size() == 1


def test_same_key_same_state_bit_for_bit_other_key_differs(foresit_run):
    state, metrics = foresit_run
    again, metrics_again = H.init_and_run(FORESIT, 0, 12)
    H.assert_trees_bitwise_equal(state, again)
    H.assert_trees_bitwise_equal(metrics, metrics_again)
    other, _ = H.init_and_run(FORESIT, 1, 12)
    assert not H.trees_bitwise_equal(state.params, other.params)
    assert not H.trees_bitwise_equal(state.imagination_params, other.imagination_params)


# ---------------------------------------------------------------------- what each loss moves
@functools.lru_cache(maxsize=None)
def _loss_term_grads(config):
    """d(policy-gradient, value, entropy terms)/d(theta, w) of one window, differentiating
    through the acting scan (so that f_w, which imagines i_tau while acting, is an input)."""
    trainer = H.trainer(dataclasses.replace(config, gradient="through_rollout"))

    def terms(params, w_params, actor, key):
        _, traj, end = trainer.act(AgentParams(params, w_params), trainer.bind(trainer.env_params), actor, key)
        _, (_, _, metrics) = trainer.window_loss(params, traj, end, actor.memory)
        return jnp.stack(
            [metrics["losses/policy_gradient_loss"], metrics["losses/value_loss"], metrics["losses/entropy"]]
        )

    return jax.jit(jax.jacrev(terms, argnums=(0, 1)), compiler_options=H.FAST_COMPILE)


def test_each_loss_term_moves_the_right_parameters():
    state = H.jitted_init(FORESIT)(jax.random.PRNGKey(0))
    d_params, d_w = _loss_term_grads(FORESIT)(
        state.params, state.imagination_params, state.actor, jax.random.PRNGKey(1)
    )
    pg, value, entropy = (jax.tree.map(lambda g, i=i: g[i], d_params) for i in range(3))

    # The value loss of Eq. 9 reaches the attention critic (q, k, v of Eq. 3-4), the value
    # MLP and, through s_t, the encoder; never the policy head.
    for name in ("query", "key", "value", "value_head"):
        assert H.max_abs(H.subtree(value, "value_critic", name)) > 0, name
    assert H.max_abs(H.subtree(value, "encoder")) > 0
    assert H.max_abs(H.subtree(value, "policy")) == 0
    # The policy-gradient term reaches the policy head and the encoder, never the critic
    # (advantages are constants of the policy loss).
    assert H.max_abs(H.subtree(pg, "policy")) > 0
    assert H.max_abs(H.subtree(pg, "encoder")) > 0
    assert H.max_abs(H.subtree(pg, "value_critic")) == 0
    assert H.max_abs(H.subtree(entropy, "policy")) > 0
    assert H.max_abs(H.subtree(entropy, "value_critic")) == 0
    # No A3C term reaches f_w: i_tau enters the policy under stop-gradient.
    assert H.max_abs(d_w) == 0


def test_imagination_loss_depends_on_fw_only():
    trainer = H.trainer(FORESIT)
    state = H.jitted_init(FORESIT)(jax.random.PRNGKey(0))
    rng = np.random.default_rng(0)
    s_0, goal, subgoal = (jnp.asarray(rng.normal(size=n), jnp.float32) for n in (16, 300, 16))
    loss = lambda w, s, g, sg: imagination.imagination_loss(trainer.networks.imagine, w, s, g, sg)  # noqa: E731
    grads = jax.jit(jax.grad(loss, argnums=(0, 1, 2, 3)), compiler_options=H.FAST_COMPILE)
    d_w, d_s0, d_goal, d_subgoal = grads(state.imagination_params, s_0, goal, subgoal)
    assert H.max_abs(d_w) > 0
    assert H.max_abs(d_subgoal) == 0  # the selected sub-goal is a fixed target
    # (s_0 and g are inputs of f_w; in training they are stored arrays, not theta.)
    assert H.max_abs(d_s0) > 0 and H.max_abs(d_goal) > 0


@pytest.mark.slow
def test_full_buffer_trains_only_fw_and_is_emptied():
    """Force lane 0's buffer full before an update: f_w is trained on it (and nothing
    else changes: theta, Adam state, trackers, key are bit-identical to the same update
    without the full buffer); the buffer is emptied; f_w moved towards the sub-goal.
    (Short windows and a seed whose update sees no success of its own.)"""
    config = H.tiny_config("a3c+foresit", num_steps=5)
    trainer, update = H.trainer(config), H.jitted_update(config)
    for seed in range(20):  # the first seed whose update sees no success of its own
        state = H.jitted_init(config)(jax.random.PRNGKey(seed))
        if int(update(state, trainer.env_params)[1]["imagination/num_trained_lanes"]) == 0:
            break
    rng = np.random.default_rng(1)
    s_0 = jnp.tanh(jnp.asarray(rng.normal(size=16), jnp.float32))
    goal = jnp.asarray(rng.normal(size=300), jnp.float32)
    subgoal = jnp.tanh(jnp.asarray(rng.normal(size=16), jnp.float32))
    b = state.buffers
    full = b._replace(
        s_0=b.s_0.at[0, 0].set(s_0),
        goal=b.goal.at[0, 0].set(goal),
        subgoal=b.subgoal.at[0, 0].set(subgoal),
        count=b.count.at[0].set(b.capacity),
    )
    plain, m_plain = update(state, trainer.env_params)
    forced, m_forced = update(state._replace(buffers=full), trainer.env_params)

    assert int(m_plain["imagination/num_trained_lanes"]) == 0  # precondition of this seed
    assert int(m_forced["imagination/num_trained_lanes"]) == 1
    for field in ("params", "opt_state", "actor", "key", "update"):
        H.assert_trees_bitwise_equal(getattr(plain, field), getattr(forced, field))
    H.assert_trees_bitwise_equal(plain.imagination_params, state.imagination_params)
    assert not H.trees_bitwise_equal(forced.imagination_params, state.imagination_params)
    assert int(forced.buffers.count[0]) == 0
    assert H.max_abs(jax.tree.map(lambda x: x[0], forced.buffers)) == 0
    loss = lambda w: imagination.imagination_loss(trainer.networks.imagine, w, s_0, goal, subgoal)  # noqa: E731
    assert float(loss(forced.imagination_params)) < float(loss(state.imagination_params))
    np.testing.assert_allclose(
        float(m_forced["imagination/first_epoch_loss"]), float(loss(state.imagination_params)), rtol=1e-5
    )


def test_buffer_of_one_trains_fw_on_every_success(foresit_run):
    """buffer_size=1: each successful episode fills its lane's buffer, which trains f_w in
    the same update.  Replays the fixture's updates to see f_w before and after each."""
    trainer, update = H.trainer(FORESIT), H.jitted_update(FORESIT)
    state = H.jitted_init(FORESIT)(jax.random.PRNGKey(0))
    successes = episodes = 0
    for _ in range(12):
        new, metrics = update(state, trainer.env_params)
        ended = int(metrics["charts/episodes"])
        successful = round(float(metrics["charts/success_rate"]) * ended)
        trained = int(metrics["imagination/num_trained_lanes"])
        assert trained == successful
        assert H.trees_bitwise_equal(new.imagination_params, state.imagination_params) == (trained == 0)
        assert int(jnp.sum(new.buffers.count)) == 0  # every buffer was emptied
        successes += successful
        episodes += ended
        state = new
    assert successes > 0, "seed 0 should see a success in 12 windows"
    H.assert_trees_bitwise_equal(state, foresit_run[0])
    # Every ended episode was recorded in its lane's moving success rate (window 100).
    assert int(np.sum(state.actor.agent.imagination.tracker.count)) == episodes
    assert float(jnp.sum(state.actor.agent.imagination.tracker.outcomes)) == successes


# ---------------------------------------------------------------------- every method
# The default tier keeps ForeSIT itself; the other methods are the slow tier's.
@pytest.mark.parametrize(
    "method", [m if m == "a3c+foresit" else pytest.param(m, marks=pytest.mark.slow) for m in H.METHODS]
)
def test_every_method_trains_without_nan(method, foresit_run):
    config = H.tiny_config(method)
    if method == "a3c+foresit":
        state, metrics = foresit_run
    else:
        state, metrics = H.init_and_run(config, 0, 2)
    H.assert_tree_finite(state)
    H.assert_tree_finite(metrics)
    assert int(state.update) == len(metrics["losses/total_loss"])
    flags = config.pieces.imagination_variant
    assert any(k.startswith("imagination/") for k in metrics) == flags.trains_imagination
    if not flags.trains_imagination:  # a3c and rnd never touch f_w
        init = H.jitted_init(config)(jax.random.PRNGKey(0))
        H.assert_trees_bitwise_equal(state.imagination_params, init.imagination_params)
        H.assert_trees_bitwise_equal(state.buffers, init.buffers)
    assert ("query" in state.params["params"]["value_critic"]) == config.pieces.attention_critic


@pytest.mark.slow
@pytest.mark.parametrize("method", H.ORG_METHODS)
def test_every_object_graph_method_trains_without_nan_on_the_org_setup(method):
    config = H.tiny_config(method, setup="org")
    state, metrics = H.init_and_run(config, 0, 2)
    H.assert_tree_finite(state)
    H.assert_tree_finite(metrics)
    graph = state.params["params"]["object_graph"]  # ORG's graph, read by the encoder
    assert "appearance_embedding" in graph and "adjacency_0" in graph
    assert config.pieces.greedy_evaluation  # ORG's evaluation takes the argmax


@pytest.mark.slow
def test_the_encoder_really_uses_the_detections():
    """ORG's graph reads the detector features: the policy logits have a non-zero gradient
    with respect to them, and blanking one visible category's detection changes them."""
    config = H.tiny_config("a3c+org", setup="org")
    trainer = H.trainer(config)
    state = H.jitted_init(config)(jax.random.PRNGKey(0))
    nets, obs = trainer.networks, jax.tree.map(lambda x: x[0], state.actor.obs)  # lane 0
    probs = jnp.zeros((config.num_actions,))

    def logits(detections):
        seen = {**obs, "detections": detections}
        from foresit_jax.lstm import initial_carry
        from foresit_jax.networks import EncoderInputs

        inputs = EncoderInputs(*jax.tree.map(lambda x: x[None], (seen, probs)))
        _, states = nets.model.apply(
            state.params, initial_carry((), config.hidden_size), inputs, jnp.ones((1,), bool), method=ActorCritic.encode
        )
        return nets.model.apply(state.params, states[0], method=ActorCritic.policy_logits)

    detections = obs["detections"]
    grad = jax.grad(lambda d: jnp.sum(logits(d) * jnp.arange(1.0, 7.0)))(detections)
    assert float(jnp.max(jnp.abs(grad))) > 0
    visible = np.flatnonzero(np.asarray(detections[:, 0]) > 0)
    if visible.size:  # blank the first visible category
        blanked = detections.at[visible[0]].set(0.0)
    else:  # nothing in view: make one category visible instead
        blanked = detections.at[0, :6].set(jnp.asarray([1.0, 0.2, 0.4, 0.0, 0.34, 0.5]))
    assert not np.allclose(logits(detections), logits(blanked))


@pytest.mark.slow
@pytest.mark.timeout(400)
def test_object_graph_training_on_an_easy_org_setting_raises_the_success_rate():
    """As the savn easy-setting test, on the org setup with ORG's encoder."""
    config = H.tiny_config(
        "a3c+org",
        setup="org",
        num_lanes=16,
        hidden_size=64,
        attention_size=64,
        value_hidden=64,
        imagination_layer_sizes=(64, 32, 16, 32, 64, 64),
        learning_rate=5e-3,
    )
    _, _, first, last = H.easy_setting_run(config, *H.org_bathroom_env())
    assert last > 0.5 and last > first + 0.25, (first, last)


# ---------------------------------------------------------------------- vmapped seed sweep
@pytest.mark.slow
def test_vmapped_sweep_matches_seeds_run_one_by_one():
    """What experiments.sweep runs: vmap(run) over seeds in one jit.  Compared with each
    seed's updates run alone (a different XLA program, so equal to float rounding: the
    batched matmuls differ in the last bits; measured max |diff| ~1e-6 after a few updates).
    """
    trainer = H.trainer(FORESIT)
    seeds = (0, 1, 2)
    init = H.jitted_init(FORESIT)
    states = jax.tree.map(lambda *x: jnp.stack(x), *[init(jax.random.PRNGKey(s)) for s in seeds])
    sweep = jax.jit(jax.vmap(trainer.run, in_axes=(0, None, None)), static_argnums=2, compiler_options=H.FAST_COMPILE)
    swept, swept_metrics = sweep(states, trainer.env_params, 3)
    for i, seed in enumerate(seeds):
        alone, alone_metrics = H.init_and_run(FORESIT, seed, 3)
        mine = jax.tree.map(lambda x: x[i], swept)
        # Discrete parts (episode outcomes, buffer fills, keys) are identical.
        H.assert_trees_bitwise_equal(mine.actor.agent.imagination.tracker, alone.actor.agent.imagination.tracker)
        H.assert_trees_bitwise_equal(mine.buffers.count, alone.buffers.count)
        H.assert_trees_bitwise_equal((mine.key, mine.update), (alone.key, alone.update))
        jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-5), mine, alone)
        for name, values in alone_metrics.items():
            np.testing.assert_allclose(np.asarray(swept_metrics[name][i]), values, rtol=1e-4, atol=1e-5, err_msg=name)


# ---------------------------------------------------------------------- a grid of learning rates
def test_grid_inputs_put_every_seed_at_every_rate_rate_major():
    keys, rates = train_module.grid_inputs([3, 5], [3e-4, 1e-3])
    np.testing.assert_array_equal(np.asarray(rates), np.float32([3e-4, 3e-4, 1e-3, 1e-3]))
    expected = [jax.random.PRNGKey(s) for s in (3, 5, 3, 5)]
    np.testing.assert_array_equal(np.asarray(keys), np.stack([np.asarray(k) for k in expected]))
    for seeds, values in (([], [1e-3]), ([0], []), ([0], [1e-3, 0.0])):
        with pytest.raises(ValueError, match="grid_inputs"):
            train_module.grid_inputs(seeds, values)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["a3c", "a3c+foresit", "a3c+maml"])
def test_the_grid_trainer_at_a_rate_trains_as_the_constant_rate_does_to_the_bit(method):
    """The rate given as an array (GridTrainer) moves every parameter, Adam moment, buffer
    and f_w weight as the config's constant rate does, bit for bit, at a rate other than
    the config's: `run`'s scan of 3 updates, unvmapped, at XLA's default compile options
    (what `train` runs)."""
    config = H.tiny_config(method, learning_rate=3e-3)
    env, env_params = H.trainer(config).env, H.trainer(config).env_params
    constant = Trainer(config, env, env_params)
    grid = train_module.GridTrainer(H.tiny_config(method), env, env_params)
    key = jax.random.PRNGKey(1)
    a, a_metrics = jax.jit(lambda k: constant.run(constant.init(k), env_params, 3))(key)
    b, b_metrics = jax.jit(lambda k, r: grid.run(grid.init(k, r), env_params, 3))(key, 3e-3)
    assert float(grid.learning_rate(b)) == np.float32(3e-3)
    H.assert_trees_bitwise_equal(b.opt_state[1].inner_state, a.opt_state[1])
    H.assert_trees_bitwise_equal(b._replace(opt_state=()), a._replace(opt_state=()))
    H.assert_trees_bitwise_equal(b_metrics, a_metrics)


@pytest.mark.slow
def test_a_vmapped_grid_is_the_per_rate_sweeps_to_float_rounding():
    """What `experiments.sweep` runs at one rate (`Trainer.run_seeds`, 2 seeds) is the
    GridTrainer's program over the same seeds at that rate, bit for bit; 2 rates x 2 seeds
    in one program equal those sweeps up to float rounding (a batch of 4 lanes instead of
    2 is another XLA program: measured up to 4e-5 on a parameter after 3 tiny updates, at
    the default compile options), with the same discrete outcomes; the rates train apart."""
    env, env_params = H.trainer(FORESIT).env, H.trainer(FORESIT).env_params
    grid = train_module.GridTrainer(FORESIT, env, env_params)
    rates, seeds = (3e-4, 3e-3), (0, 1)
    keys, values = train_module.grid_inputs(seeds, rates)
    init = jax.jit(jax.vmap(grid.init))
    together, together_metrics = grid.run_seeds(init(keys, values), env_params, 3)
    np.testing.assert_array_equal(np.asarray(grid.learning_rate(together)), np.float32([3e-4, 3e-4, 3e-3, 3e-3]))
    for v, rate in enumerate(rates):
        sweep = Trainer(dataclasses.replace(FORESIT, learning_rate=rate), env, env_params)
        alone, alone_metrics = sweep.run_seeds(jax.jit(jax.vmap(sweep.init))(keys[: len(seeds)]), env_params, 3)
        one_rate, _ = grid.run_seeds(init(*train_module.grid_inputs(seeds, [rate])), env_params, 3)
        H.assert_trees_bitwise_equal(one_rate.opt_state[1].inner_state, alone.opt_state[1])
        H.assert_trees_bitwise_equal(one_rate._replace(opt_state=()), alone._replace(opt_state=()))
        part = jax.tree.map(lambda x: x[v * len(seeds) : (v + 1) * len(seeds)], together)
        H.assert_trees_bitwise_equal(
            (part.actor.agent.imagination.tracker, part.buffers.count, part.key, part.update),
            (alone.actor.agent.imagination.tracker, alone.buffers.count, alone.key, alone.update),
        )
        jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-3, atol=2e-4), part.params, alone.params)
        for name, values_ in alone_metrics.items():
            np.testing.assert_allclose(
                np.asarray(together_metrics[name][v * len(seeds) : (v + 1) * len(seeds)]),
                values_,
                rtol=1e-3,
                atol=2e-4,
                err_msg=name,
            )
    kernel = np.asarray(jax.tree.leaves(together.params)[0])
    assert not np.array_equal(kernel[0], kernel[2]), "seed 0 trained the same at both rates"


# ---------------------------------------------------------------------- learning
@pytest.mark.slow
@pytest.mark.timeout(400)
def test_training_on_an_easy_setting_raises_the_success_rate():
    """One bathroom, one target, starts at most 3 actions from success: a random policy
    succeeds ~15% of the time; 150 updates of 16 lanes lift ForeSIT far above that.
    (Measured, seeds 0-7: the last 20 updates succeed 76-91% of the time; with 32 hidden
    units instead of 64, about half the seeds were still stuck at ~15% after 300 updates.)
    """
    config = H.tiny_config(
        "a3c+foresit",
        num_lanes=16,
        hidden_size=64,
        attention_size=64,
        value_hidden=64,
        imagination_layer_sizes=(64, 32, 16, 32, 64, 64),
        buffer_size=4,
        imagination_epochs=5,
        learning_rate=5e-3,
    )
    _, _, first, last = H.easy_setting_run(config, *H.bathroom_env())
    assert first < 0.3, first
    assert last > 0.5 and last > first + 0.25, (first, last)


@pytest.mark.slow
def test_the_progress_callback_sees_every_update_and_changes_no_number():
    """`Trainer.run`'s on_update (the progress bar inside a chunk) is called after every
    PROGRESS_EVERY-th update with the update count (vmapped over seeds: after every update,
    once per seed), and the states and metrics are those of a run without it, bit for bit.
    The callback lives in the update loop, which every method shares: a3c is the cheapest
    to compile."""
    config = H.tiny_config("a3c")
    trainer = H.trainer(config)
    state = H.jitted_init(config)(jax.random.PRNGKey(3))
    seen = []
    n = 2 * train_module.PROGRESS_EVERY + 1
    jit = functools.partial(jax.jit, static_argnums=2, compiler_options=H.FAST_COMPILE)
    plain = jit(trainer.run)(state, trainer.env_params, n)
    reported = jit(functools.partial(trainer.run, on_update=lambda u: seen.append(np.asarray(u).tolist())))(
        state, trainer.env_params, n
    )
    jax.block_until_ready(reported)
    H.assert_trees_bitwise_equal(plain, reported)
    assert seen == [train_module.PROGRESS_EVERY, 2 * train_module.PROGRESS_EVERY]
    states = jax.vmap(trainer.init)(jax.random.split(jax.random.PRNGKey(4), 2))
    seen.clear()
    plain = trainer.run_seeds(states, trainer.env_params, 2)
    reported = train_module.seeds_runner(trainer, lambda u: seen.append(np.asarray(u).tolist()))(
        states, trainer.env_params, 2
    )
    jax.block_until_ready(reported)
    H.assert_trees_bitwise_equal(plain, reported)
    assert sorted(seen) == [1, 1, 2, 2], seen  # vmapped: once per seed and update
