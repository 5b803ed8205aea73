"""foresit_jax.rollout: parameter trees per method, the shared rollout (invariants against
the environment's rules), the replay's values, the critic, and episode statistics
against hand-computed values."""

import functools

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import train_helpers as H
from foresit_jax.config import Config
from foresit_jax.lstm import initial_carry
from foresit_jax.networks import build
from foresit_jax.rollout import (
    ActOptions,
    AgentParams,
    BoundEnv,
    EpisodeStats,
    Trajectory,
    WindowEnd,
    ended_episodes,
    episode_stats,
)
from foresit_jax.rollout import rollout as rollout_of
from foresit_jax.train import replayed as replay_of
from foresit_jax.train import window_critic

DONE = 5
LANES = 8
FORESIT = H.tiny_config("a3c+foresit")


def observation():
    env, env_params = H.bathroom_env()
    return jax.tree.map(np.asarray, env.reset(jax.random.PRNGKey(0), env_params)[0])


# ---------------------------------------------------------------------- parameters
def test_a_linear_value_head_is_one_dense_layer_for_every_critic():
    for method in ("a3c", "a3c+foresit"):
        config = H.tiny_config(method, value_head="linear")
        params, _ = jax.eval_shape(build(config).init, jax.random.PRNGKey(0), observation())
        head = params["params"]["value_critic"]["value_head"]
        assert set(head) == {"out"} and head["out"]["kernel"].shape == (config.hidden_size, 1)


@pytest.mark.parametrize("method", H.METHODS)
def test_parameter_tree_of_each_method(method):
    config = H.tiny_config(method)
    obs = observation()
    params, w_params = jax.eval_shape(build(config).init, jax.random.PRNGKey(0), obs)
    flags, hidden = config.pieces.imagination_variant, config.hidden_size
    critic = params["params"]["value_critic"]
    # Only the attention critic has q, k, v (Eq. 3-4); the plain A3C critic is an MLP.
    assert {"query", "key", "value"} <= set(critic) if config.pieces.attention_critic else set(critic) == {"value_head"}
    # The policy is linear over [s_t : i_tau] with imagination, over s_t without.
    policy_inputs = 2 * hidden if flags.uses_imagination else hidden
    chex.assert_shape(params["params"]["policy"]["actor"]["kernel"], (policy_inputs, config.num_actions))
    # f_w maps [s_0 : g_tau] to an imagined state.
    layers = w_params["params"]
    assert len(layers) == len(config.imagination_layer_sizes)
    chex.assert_shape(
        layers["layer_0"]["kernel"], (hidden + obs["target"].shape[-1], config.imagination_layer_sizes[0])
    )
    chex.assert_shape(layers[f"layer_{len(layers) - 1}"]["kernel"], (config.imagination_layer_sizes[-2], hidden))


# ---------------------------------------------------------------------- episode statistics
def test_episode_stats_hand_computed():
    T, B = 5, 5
    valid = np.zeros((T, B), bool)
    terminated = np.zeros((T, B), bool)
    truncated = np.zeros((T, B), bool)
    success = np.zeros((T, B), bool)
    # lane 0: success on the 4th action, L^g = 2     -> L 4, SPL 2/4
    valid[:4, 0], terminated[3, 0], success[3, 0] = True, True, True
    # lane 1: Done at once, failed                  -> L 1, SPL 0
    valid[:1, 1], terminated[0, 1] = True, True
    # lane 2: time limit at the 5th step             -> L 5, ended, SPL 0
    valid[:, 2], truncated[4, 2] = True, True
    # lane 3: optimal success (L = L^g = 3)          -> SPL 1
    valid[:3, 3], terminated[2, 3], success[2, 3] = True, True, True
    # lane 4: still running at the end of the rollout, and garbage after a lane's end
    valid[:, 4] = True
    success[4, 1] = terminated[4, 1] = True  # padding of lane 1: ignored
    traj = Trajectory(
        states=np.zeros((T, B, 2), np.float32),
        logits=np.zeros((T, B, 6), np.float32),
        actions=np.zeros((T, B), np.int32),
        rewards=np.zeros((T, B), np.float32),
        terminated=terminated,
        truncated=truncated,
        valid=valid,
        success=success,
        episode_step=np.broadcast_to(np.arange(T)[:, None], (T, B)).astype(np.int32),
        s_0=np.zeros((T, B, 2), np.float32),
        optimal_length=np.broadcast_to(np.array([2, 3, 4, 3, 6], np.int32), (T, B)),
        room_type=np.full((T, B), 3, np.int32),
    )
    stats = jax.tree.map(np.asarray, episode_stats(traj))
    assert isinstance(stats, EpisodeStats)
    np.testing.assert_array_equal(stats.success, [True, False, False, True, False])
    np.testing.assert_array_equal(stats.length, [4, 1, 5, 3, 5])
    np.testing.assert_array_equal(stats.ended, [True, True, True, True, False])
    np.testing.assert_allclose(stats.spl, [0.5, 0.0, 0.0, 1.0, 0.0])
    np.testing.assert_array_equal(stats.optimal_length, [2, 3, 4, 3, 6])
    # The same episodes seen as a packed window: one entry per ended episode, at its end.
    ended, per_step = jax.tree.map(np.asarray, ended_episodes(traj))
    np.testing.assert_array_equal(ended.sum(0), [1, 1, 1, 1, 0])
    np.testing.assert_allclose(per_step.spl.T[ended.T], [0.5, 0.0, 0.0, 1.0])  # lane order
    np.testing.assert_array_equal(per_step.length.T[ended.T], [4, 1, 5, 3])


# ---------------------------------------------------------------------- the shared rollout
@functools.lru_cache(maxsize=None)
def _rollout(greedy: bool):
    """jit(rollout with recorded inputs, then replay) of the tiny ForeSIT agent, once."""
    nets, (env, _) = build(FORESIT), H.bathroom_env()

    def run(params, w_params, env_params, key, sigma2):
        traj = rollout_of(
            nets,
            AgentParams(params, w_params, sigma2),
            BoundEnv(env, env_params),
            key,
            FORESIT.num_steps,
            ActOptions(greedy=greedy, record_inputs=not greedy),
        )
        again = None if greedy else replay_of(nets, params, traj, initial_carry((LANES,), FORESIT.hidden_size))
        replayed = None if greedy else (again.states, again.logits)
        memory = jnp.zeros((LANES, 0, FORESIT.hidden_size))
        end = WindowEnd(
            jnp.zeros((LANES, FORESIT.hidden_size)), jnp.zeros((LANES,), jnp.int32)
        )  # whole episodes: nothing bootstrapped
        return traj, replayed, window_critic(nets, params, traj, end, memory)[0]

    return jax.jit(run, compiler_options=H.FAST_COMPILE)


@pytest.fixture(scope="module")
def rollout():
    """A sampled rollout of 8 lanes with freshly initialised parameters."""
    env, env_params = H.bathroom_env()
    params, w_params = jax.jit(build(FORESIT).init, compiler_options=H.FAST_COMPILE)(
        jax.random.PRNGKey(0), observation()
    )
    sigma2 = jnp.full((LANES,), 0.5)
    out = _rollout(False)(params, w_params, env_params, jax.random.PRNGKey(1), sigma2)
    return (params, w_params, env_params, sigma2), jax.tree.map(np.asarray, out)


def test_rollout_follows_the_environment_rules(rollout):
    _, (traj, _, _) = rollout
    T = FORESIT.num_steps
    chex.assert_shape([traj.actions, traj.rewards, traj.valid, traj.success], (T, LANES))
    chex.assert_shape(traj.states, (T, LANES, FORESIT.hidden_size))
    chex.assert_shape(traj.logits, (T, LANES, FORESIT.num_actions))
    valid = traj.valid
    assert valid[0].all()
    assert (valid[1:] <= valid[:-1]).all(), "a lane's episode is a prefix of the rollout"
    ends = (traj.terminated | traj.truncated) & valid
    assert (ends.sum(0) == 1).all(), "num_steps >= the time limit: every episode ends exactly once"
    length = valid.sum(0)
    last = length - 1
    lanes = np.arange(LANES)
    assert ends[last, lanes].all(), "the episode ends at its last valid step"
    # Done always ends the episode, and only Done terminates it (SAVN's rule).
    np.testing.assert_array_equal(traj.terminated & valid, (traj.actions == DONE) & valid)
    # Success only on a Done; +5 on a successful Done, -0.01 on every other real step.
    assert not (traj.success & ~traj.terminated).any()
    assert not (traj.success & ~valid).any()
    np.testing.assert_allclose(traj.rewards[valid], np.where(traj.success, 5.0, -0.01)[valid])
    # The time limit (30 for training) is truncation, after exactly 30 actions.
    np.testing.assert_array_equal(traj.truncated[last, lanes] & ~traj.terminated[last, lanes], length == 30)
    assert (traj.optimal_length >= 2).all(), "never solved at the start, Done counted"
    assert (traj.actions >= 0).all() and (traj.actions < FORESIT.num_actions).all()
    assert np.isfinite(traj.logits).all()
    assert (np.abs(traj.states) < 1).all()  # LSTM h = o * tanh(c)


def test_replay_recomputes_the_acting_pass(rollout):
    """Training differentiates the replay (`replayed`): on the real steps it must give what the agent
    computed while acting (up to float rounding: the encoder runs batched over the window)."""
    _, (traj, (states, logits), _) = rollout
    valid = traj.valid
    np.testing.assert_allclose(states[valid], traj.states[valid], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(logits[valid], traj.logits[valid], rtol=1e-5, atol=1e-6)


def test_critic_over_each_lane_episode(rollout):
    _, (traj, _, critic) = rollout
    T = FORESIT.num_steps
    chex.assert_shape(critic.value, (T + 1, LANES))  # row T: the state after the window
    chex.assert_shape(critic.alpha, (LANES, T + 1, T + 1))
    alpha = critic.alpha
    valid = traj.valid.T  # [B, T]
    for b in range(LANES):
        n = int(valid[b].sum())
        # Attention of each real step over the real steps up to it (Eq. 3), summing to 1.
        np.testing.assert_allclose(alpha[b, :n, :n].sum(-1), 1.0, rtol=1e-5)
        assert (np.triu(alpha[b, :n, :n], 1) == 0).all()
        assert (alpha[b, :n, n:] == 0).all()
    assert np.isfinite(critic.value[:T][traj.valid]).all()


def test_greedy_rollout_takes_the_most_likely_action(rollout):
    (params, w_params, env_params, sigma2), (sampled, _, _) = rollout
    traj, _, _ = jax.tree.map(np.asarray, _rollout(True)(params, w_params, env_params, jax.random.PRNGKey(1), sigma2))
    valid = traj.valid
    np.testing.assert_array_equal(traj.actions[valid], traj.logits.argmax(-1)[valid])
    # Same key, same start states: only the action choice differs.
    np.testing.assert_array_equal(traj.optimal_length[0], sampled.optimal_length[0])
    np.testing.assert_array_equal(traj.room_type[0], sampled.room_type[0])
    assert (sampled.actions[sampled.valid] != sampled.logits.argmax(-1)[sampled.valid]).any()


def test_a_config_refuses_an_unknown_evaluation_noise_or_imagination_input():
    with pytest.raises(ValueError, match="evaluation_noise"):
        Config(evaluation_noise="none")
    with pytest.raises(ValueError, match="imagination_input"):
        Config(imagination_input="policy")
