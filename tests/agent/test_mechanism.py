"""The pieces the mechanism study turns (docs/mechanism.md), against independent references:
where i_tau enters (`Config.imagination_input`), i_tau while acting, the sub-goal the
buffers get, the evaluation noise, the critic and the sweep's diagnostics. The probes' own
tests (`experiments.analysis.probes`) are tests/experiments/test_probes.py."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import train_helpers as H
from foresit_jax import rollout
from foresit_jax.config import Config
from foresit_jax.evaluate import agent_params
from foresit_jax.imagination import subgoal_items, subgoal_steps
from foresit_jax.networks import build
from foresit_jax.rollout import AgentParams, BoundEnv
from foresit_jax.networks import ActorCritic
from test_networks import np_attention_critic, np_dense

relu = lambda x: np.maximum(x, 0.0)  # noqa: E731


def observation(batch=4, seed=0):
    env, env_params = H.bathroom_env()
    obs, _ = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(jax.random.PRNGKey(seed), batch), env_params)
    return obs


def scrambled(params, seed=1, scale=0.5):
    """The same tree with N(0, scale^2) leaves: far from the near-uniform initial policy
    and attention, so that inputs visibly matter and argmaxes have no near-ties."""
    rng = np.random.default_rng(seed)
    return jax.tree.map(lambda x: jnp.asarray(rng.normal(size=x.shape) * scale, x.dtype), params)


# ---------------------------------------------------------------------- where i_tau enters
@pytest.mark.slow
def test_the_encoder_reading_feeds_i_tau_beside_the_target():
    """imagination_input='encoder': the LSTM's input is the 1x1 conv of [view features :
    tile(g) : tile(action) : tile(i_tau embedded)], built here by hand in numpy; the head
    sees s_t alone."""
    config = H.tiny_config("a3c+foresit", imagination_input="encoder")
    nets = build(config)
    obs = observation()
    params, _ = nets.init(jax.random.PRNGKey(0), jax.tree.map(lambda x: x[0], obs))

    def lstm_inputs(params, obs, probs, imagined=None):
        return nets.model.apply(params, obs, probs, imagined, method=ActorCritic.encoder_features)

    params = scrambled(params)
    rng = np.random.default_rng(0)
    probs = np.asarray(jax.nn.softmax(rng.normal(size=(4, config.num_actions))), np.float32)
    imagined = np.tanh(rng.normal(size=(4, config.hidden_size))).astype(np.float32)
    got = np.asarray(lstm_inputs(params, obs, probs, imagined))

    p = jax.tree.map(lambda x: np.asarray(x, np.float64), params["params"]["encoder"])
    view = np.asarray(obs["view"], np.float64)
    for b in range(4):
        vectors = [
            relu(np_dense(p["target_embed"], obs["target"][b])),
            relu(np_dense(p["action_embed"], probs[b])),
            relu(np_dense(p["imagination_embed"], imagined[b])),
        ]
        cells = [
            relu(
                np_dense(p["pointwise_conv"], np.concatenate([relu(np_dense(p["view_conv"], view[b, r, c])), *vectors]))
            )
            for r in range(view.shape[1])
            for c in range(view.shape[2])
        ]
        np.testing.assert_allclose(got[b], np.concatenate(cells), rtol=2e-4, atol=2e-5)
    # i_tau changes the input; the policy head takes s_t alone.
    assert np.abs(got - np.asarray(lstm_inputs(params, obs, probs, 0 * imagined))).max() > 1e-3
    assert params["params"]["policy"]["actor"]["kernel"].shape == (config.hidden_size, config.num_actions)
    with pytest.raises(ValueError, match="needs i_tau"):
        lstm_inputs(params, obs, probs)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["a3c+foresit", "a3c"])
def test_the_mlp_reading_is_a_two_layer_head(method):
    """imagination_input='mlp': logits = Dense(ReLU(Dense([s_t : i_tau]))), and the base gets
    the same MLP over s_t (so a pair changes one thing)."""
    config = H.tiny_config(method, imagination_input="mlp")
    nets = build(config)
    obs = jax.tree.map(lambda x: x[0], observation())
    params, _ = nets.init(jax.random.PRNGKey(0), obs)
    params = scrambled(params)
    rng = np.random.default_rng(1)
    s_t, i_tau = (np.tanh(rng.normal(size=(3, config.hidden_size))).astype(np.float32) for _ in range(2))
    uses = config.pieces.imagination_variant.uses_imagination
    got = nets.model.apply(
        params, s_t, i_tau, method=ActorCritic.policy_logits
    )  # i_tau dropped where the head takes none
    p = jax.tree.map(np.asarray, params["params"]["policy"])
    x = np.concatenate([s_t, i_tau], -1) if uses else s_t
    np.testing.assert_allclose(got, np_dense(p["actor"], relu(np_dense(p["hidden"], x))), rtol=1e-4, atol=1e-5)


# ---------------------------------------------------------------------- i_tau while acting
@pytest.mark.slow
@pytest.mark.parametrize("method, reading", [("a3c+foresit", "head"), ("a3c+foresit", "encoder"), ("a3c+int", "head")])
def test_i_tau_while_acting_is_f_w_of_the_episode_state_it_was_renewed_at(method, reading):
    """Without noise, every step's i_tau equals f_w([s_k : g]) with k the episode's first
    step (every K-th step for `int`), so it is constant between renewals; with
    imagination_input='encoder' the encoder gets it from the step after the first (zeros
    at the first) and the head gets none. With noise, i_tau - f_w has the noise's variance
    and is constant over the episode."""
    config = H.tiny_config(method, imagination_input=reading, int_interval=4, num_steps=30)
    nets = build(config)
    env, env_params = H.bathroom_env()
    obs = jax.tree.map(lambda x: x[0], observation())
    params, w_params = nets.init(jax.random.PRNGKey(0), obs)
    params, w_params = scrambled(params, 1, 0.3), scrambled(w_params, 2, 0.5)
    lanes = 8

    @jax.jit
    def act(variance, key):
        bound = BoundEnv(env, env_params)
        actor = rollout.start(nets, jax.random.PRNGKey(5), bound, lanes)
        return rollout.act_window(nets, AgentParams(params, w_params, variance), bound, actor, key, 30)[1]

    traj = jax.tree.map(np.asarray, act(jnp.zeros(lanes), jax.random.PRNGKey(6)))
    seen = traj.inputs
    given = seen.encoder_imagined if reading == "encoder" else seen.imagined
    assert (seen.imagined is None) == (reading == "encoder")
    step, states, goal = traj.episode_step, traj.states, seen.obs["target"]
    interval = config.int_interval if config.pieces.imagination_variant.renew_every_k else 10**6
    checked = 0
    for t in range(30):
        for b in range(lanes):
            k = t - step[t, b] % interval  # the step i_tau was last imagined at
            if reading == "encoder":  # the encoder sees the i_tau imagined up to the step before
                if step[t, b] == 0:
                    np.testing.assert_array_equal(given[t, b], 0.0)
                    continue
                k = t - 1 - (step[t, b] - 1) % interval
            want = nets.imagine(w_params, states[k, b], goal[k, b])
            np.testing.assert_allclose(given[t, b], want, rtol=1e-5, atol=1e-6)
            checked += 1
    assert checked > 100 and (step == 0).sum() > lanes, "precondition: several episodes per lane"

    noisy = jax.tree.map(np.asarray, act(jnp.full(lanes, 0.25), jax.random.PRNGKey(6)))
    given = noisy.inputs.encoder_imagined if reading == "encoder" else noisy.inputs.imagined
    residual = given - np.asarray(nets.imagine(w_params, noisy.s_0, noisy.inputs.obs["target"]))
    if method == "a3c+foresit":  # constant over the episode: the same residual at every step
        for t in range(1, 30):
            same = noisy.episode_step[t] > (1 if reading == "encoder" else 0)
            np.testing.assert_allclose(residual[t][same], residual[t - 1][same], atol=1e-6)
        firsts = residual[noisy.episode_step == (1 if reading == "encoder" else 0)]
        assert abs(firsts.std() - 0.5) < 0.05


# ---------------------------------------------------------------------- the sub-goal
def _two_windows(method, seed=0):
    config = H.tiny_config(method, num_steps=8)
    trainer = H.trainer(config)
    state = H.jitted_init(config)(jax.random.PRNGKey(seed))
    state = state._replace(params=scrambled(state.params, 3, 1.0))
    actor, key, out = state.actor, state.key, []

    @jax.jit
    def window(actor, key):
        env = trainer.bind(trainer.env_params)
        actor, key, k_act = trainer.begin_window(actor, key, env)
        memory = actor.memory
        next_actor, traj, end = trainer.act(AgentParams(state.params, state.imagination_params), env, actor, k_act)
        _, (alpha, keys, _) = trainer.window_loss(state.params, traj, end, memory)
        items = subgoal_items(trainer.networks.imagination_variant.subgoal_mode, traj, alpha, keys, traj.success)
        return next_actor, key, (traj, items, subgoal_steps(traj.episode_step, end.episode_step, alpha))

    for _ in range(3):
        actor, key, got = window(actor, key)
        out.append(jax.tree.map(np.asarray, got))
    return state, jax.tree.map(lambda *x: np.concatenate(x), *out)


def test_the_sub_goal_is_the_argmax_of_the_attention_row_over_the_whole_episode():
    """Packed windows (an episode's earlier states from the critic's memory): the sub-goal
    each step offers the buffer, and its position t*, are those of the argmax of that
    step's row of Eq. 4 computed by numpy over the episode's states from its first step
    (at the Done step: the paper's ŝ_tau)."""
    state, (traj, items, t_star) = _two_windows("a3c+foresit")
    p = jax.tree.map(lambda x: np.asarray(x, np.float64), state.params["params"]["value_critic"])
    subgoal, step = items[2], traj.episode_step
    checked = crossing = 0
    for b in range(step.shape[1]):
        for t in range(step.shape[0]):
            start = t - step[t, b]
            episode = traj.states[start : t + 1, b].astype(np.float64)
            _, alpha = np_attention_critic(p, episode, np.ones(len(episode), bool))
            row = alpha[-1]
            assert row[t_star[t, b]] >= row.max() - 1e-5, "t* is (up to ties) the argmax of the row"
            np.testing.assert_allclose(subgoal[t, b], episode[t_star[t, b]], rtol=1e-5, atol=1e-6)
            checked += 1
            crossing += start < (t // 8) * 8  # the episode began in an earlier window
    assert checked == step.size and crossing > 10, "precondition: episodes that cross a window's edge"


@pytest.mark.slow
def test_without_the_attention_critic_the_sub_goal_is_the_done_step_state():
    _, (traj, items, t_star) = _two_windows("a3c+foresit+plaincritic")
    np.testing.assert_array_equal(items[2], traj.states)
    np.testing.assert_array_equal(t_star, traj.episode_step)


# ---------------------------------------------------------------------- evaluation noise
def test_evaluation_noise_off_zeroes_the_variance():
    config = H.tiny_config("a3c+foresit")
    state = H.jitted_init(config)(jax.random.PRNGKey(0))
    trained = agent_params(state, 0.9, "training_end")
    assert float(trained.noise_variance) == pytest.approx(0.9)  # rho = 0 at the start
    assert float(agent_params(state, 0.9, "off").noise_variance) == 0.0
    with pytest.raises(ValueError, match="evaluation_noise"):
        Config(evaluation_noise="none")
    with pytest.raises(ValueError, match="imagination_input"):
        Config(imagination_input="policy")


# ---------------------------------------------------------------------- the critic
def test_a_method_is_parsed_with_its_critic_into_the_network():
    """`a3c+critic` has the attention critic's q, k, v and a plain linear head over s_t."""
    config = H.tiny_config("a3c+critic")
    params, _ = jax.eval_shape(build(config).init, jax.random.PRNGKey(0), jax.tree.map(lambda x: x[0], observation()))
    assert {"query", "key", "value", "value_head"} == set(params["params"]["value_critic"])
    assert params["params"]["policy"]["actor"]["kernel"].shape == (config.hidden_size, config.num_actions)
    assert dataclasses.replace(config, method="a3c").pieces.attention_critic is False


def test_a_zero_initialised_attention_value_starts_as_the_plain_critic():
    """Config.attention_value_init='zeros': s*_t = s_t at initialisation, so the attention
    critic's values equal the plain critic's MLP on s_t (the same value-head parameters),
    whatever the attention weighs; with lecun-normal v they differ."""
    from foresit_jax import networks

    rng = np.random.default_rng(0)
    states = np.tanh(rng.normal(size=(2, 7, 16))).astype(np.float32)
    valid = np.ones((2, 7), bool)
    for zero, equal in ((True, True), (False, False)):
        critic = networks.Critic(attention=True, attention_size=8, value_hidden=12, zero_value_init=zero)
        params = critic.init(jax.random.PRNGKey(1), states, valid)
        out = critic.apply(params, states, valid)
        plain = networks.ValueHead(12).apply({"params": params["params"]["value_head"]}, states)
        assert np.allclose(out.value, plain, atol=1e-6) == equal
        assert np.allclose(out.attended_state, states, atol=1e-7) == equal
    with pytest.raises(ValueError, match="attention_value_init"):
        Config(attention_value_init="ones")


def test_stopped_key_gradient_leaves_the_values_and_cuts_the_earlier_states_gradient():
    """Config.attention_key_gradient='stopped': the same values; d V(s*_t) / d s_j is zero
    for every earlier state j < t (s_j enters V(s*_t) through k and v alone), where with
    'full' it is not; d V(s*_t) / d s_t keeps the query's and the residual's part. The
    reference: the Jacobian of the full critic with k and v fed a constant copy of the
    states (so that only the query and the residual see the argument)."""
    from foresit_jax import networks

    rng = np.random.default_rng(0)
    states = np.tanh(rng.normal(size=(5, 16))).astype(np.float32)
    valid = np.ones(5, bool)
    full, stopped = (
        networks.Critic(attention=True, attention_size=8, value_hidden=12, key_gradient=g) for g in (True, False)
    )
    params = full.init(jax.random.PRNGKey(1), states, valid)
    mask = networks.causal_episode_mask(valid)
    value = {
        name: (lambda x, c=c: c.apply(params, x, valid).value) for name, c in (("full", full), ("stopped", stopped))
    }
    np.testing.assert_array_equal(value["full"](states), value["stopped"](states))
    jac = {name: np.asarray(jax.jacrev(f)(states)) for name, f in value.items()}  # [T, T, H]: d V_t / d s_j
    earlier = np.tril(np.ones((5, 5), bool), -1)
    assert np.all(jac["stopped"][earlier] == 0)
    assert np.all(np.abs(jac["full"][earlier]).max(-1) > 0)
    reference = jax.jacrev(lambda x: full.apply(params, x, valid, keys=jnp.asarray(states), key_mask=mask).value)(
        states
    )
    np.testing.assert_allclose(jac["stopped"], reference, atol=1e-6)
    config = H.tiny_config("a3c+critic", attention_key_gradient="stopped")
    assert build(config).model.key_gradient is False and build(H.tiny_config("a3c+critic")).model.key_gradient is True
    with pytest.raises(ValueError, match="attention_key_gradient"):
        Config(attention_key_gradient="none")


# ---------------------------------------------------------------------- the sweep's diagnostics
def test_explained_variance_and_advantage_spread_against_numpy():
    from foresit_jax import train

    rng = np.random.default_rng(0)
    returns, values = rng.normal(size=(6, 3)), rng.normal(size=(6, 3))
    mask = rng.random((6, 3)) > 0.3
    r, v = returns[mask], values[mask]
    want = 1 - np.var(r - v) / np.var(r)
    got = train.explained_variance(jnp.asarray(values), jnp.asarray(returns), jnp.asarray(mask))
    assert float(got) == pytest.approx(want, rel=1e-5)
    assert float(
        train.explained_variance(jnp.asarray(returns), jnp.asarray(returns), jnp.asarray(mask))
    ) == pytest.approx(1.0)
    assert float(train.masked_variance(jnp.asarray(returns), jnp.asarray(mask))) == pytest.approx(np.var(r), rel=1e-5)
    assert float(train.explained_variance(jnp.ones((4,)), jnp.zeros((4,)), jnp.ones((4,), bool))) == 0.0  # no spread


def test_sweep_diagnostics_table_by_hand():
    from experiments.reporting import report

    seed = lambda x: {"diagnostics": {n: [x, 2 * x, 3 * x] for n in report.DIAGNOSTICS[:-1]}}  # noqa: E731
    md = report.diagnostics_markdown({"a3c": [seed(1.0), seed(3.0)], "other": [{}]})
    lines = [line for line in md.splitlines() if line.startswith("| a3c")]
    assert [line.split(" | ")[1] for line in lines] == ["1/3", "2/3", "3/3"]  # first, middle, last chunk
    assert lines[2].split(" | ")[2] == "6"  # mean over the seeds of 3 and 9
    assert lines[0].rstrip(" |").endswith("| 2") and lines[0].endswith("|  |")  # no f_w loss recorded
    assert "other" not in md and report.diagnostics_markdown({"x": [{}]}) == ""
