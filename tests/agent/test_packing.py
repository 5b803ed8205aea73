"""Packed windows (Config.rollout='packed'): lanes never idle, episodes back to back, an
episode cut at a window's edge carried into the next update.

* the attention mask of a packed window against a brute-force loop;
* a window cut in two gives the forward values (states, logits, attended states, values)
  of the same steps run as one window, and the value bootstrapping the cut is V(s*_T);
* packing changes nothing but speed: the loss and its gradient over a window holding
  several complete episodes equal those of the same episodes laid out one per lane, whole
  (zero carry, no memory, padded), as SAVN's updates do;
* the bootstrapped return at a cut against a hand computation;
* the ForeSIT bookkeeping (tracker, buffer) fires once per ended episode, never for a cut one.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import train_helpers as H
from foresit_jax import rollout, train
from foresit_jax.networks import window_attention_mask
from foresit_jax.rollout import ActOptions, AgentParams, WindowEnd
from foresit_jax.train import Trainer, replayed, window_critic

# Random bathroom episodes last ~6 steps: a 40-step window holds several per lane.
PACKED = H.tiny_config("a3c+foresit", num_steps=40, num_lanes=4, buffer_size=64)


# ---------------------------------------------------------------------- the mask
def mask_by_loop(episode_step, memory_size):
    T = len(episode_step)
    episode, ids = 0, []
    for s in episode_step:
        episode += s == 0
        ids.append(episode)
    mask = np.zeros((T, memory_size + T), bool)
    for t in range(T):
        if ids[t] == 0:  # the episode running when the window began
            mask[t, : episode_step[0]] = True
        for j in range(t + 1):
            mask[t, memory_size + j] = ids[j] == ids[t]
    return mask


@pytest.mark.parametrize(
    "episode_step",
    [[3, 4, 5, 0, 1, 0, 1, 2], [0, 1, 2, 3, 0, 0, 1, 2], [5, 6, 7, 8, 9, 10, 11, 12], [0, 0, 0, 1, 2, 0, 1, 0]],
)
def test_window_attention_mask_against_a_loop(episode_step):
    np.testing.assert_array_equal(window_attention_mask(jnp.asarray(episode_step), 6), mask_by_loop(episode_step, 6))
    # Batched over lanes.
    both = jnp.asarray([episode_step, episode_step[::-1]])
    assert window_attention_mask(both, 6).shape == (2, 8, 14)


# ---------------------------------------------------------------------- cut vs uncut
@functools.lru_cache(maxsize=None)
def _act(num_steps):
    trainer = H.trainer(PACKED)

    def act(params, w_params, env_params, actor, step_keys):
        return rollout.act_window(
            trainer.networks,
            AgentParams(params, w_params),
            trainer.bind(env_params),
            actor,
            step_keys[0],
            num_steps,
            ActOptions(step_keys=step_keys),
        )

    return jax.jit(act, compiler_options=H.FAST_COMPILE)


@functools.lru_cache(maxsize=None)
def _critic():
    trainer = H.trainer(PACKED)
    return jax.jit(functools.partial(window_critic, trainer.networks), compiler_options=H.FAST_COMPILE)


@pytest.fixture(scope="module")
def windows():
    """One 40-step window, and the same steps as windows of 15 and 25 (same step keys)."""
    trainer = H.trainer(PACKED)
    state = H.jitted_init(PACKED)(jax.random.PRNGKey(3))
    keys = jax.random.split(jax.random.PRNGKey(4), 40)
    args = (state.params, state.imagination_params, trainer.env_params)
    long_actor, long, long_end = _act(40)(*args, state.actor, keys)
    cut_actor, first, first_end = _act(15)(*args, state.actor, keys[:15])
    end_actor, second, second_end = _act(25)(*args, cut_actor, keys[15:])
    return state, (long_actor, long, long_end), (cut_actor, first, first_end), (end_actor, second, second_end)


def test_a_cut_window_gives_the_forward_values_of_the_uncut_one(windows):
    state, (long_actor, long, long_end), (cut_actor, first, first_end), (end_actor, second, second_end) = windows
    for name in ("actions", "episode_step", "terminated", "truncated", "success"):
        np.testing.assert_array_equal(
            np.concatenate([getattr(first, name), getattr(second, name)]), getattr(long, name)
        )
    for name in ("states", "logits"):
        np.testing.assert_allclose(
            np.concatenate([getattr(first, name), getattr(second, name)]), getattr(long, name), rtol=1e-6, atol=1e-6
        )
    cut_episodes = np.asarray(first.episode_step[-1] > 0) & ~np.asarray(first.terminated[-1] | first.truncated[-1])
    assert cut_episodes.any(), "precondition: some lane's episode runs across the cut"
    # The state after the first window is the second window's first state.
    np.testing.assert_allclose(first_end.state, long.states[15], rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(first_end.episode_step, long.episode_step[15])
    # The lanes end in the same state.
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-6), end_actor, long_actor)

    # The critic of the second window, with the memory of the first, attends to the same
    # states with the same weights as the uncut window (Eq. 3-4 over the whole episode).
    critic = _critic()
    long_out, _ = critic(state.params, long, long_end, state.actor.memory)
    first_out, _ = critic(state.params, first, first_end, state.actor.memory)
    second_out, _ = critic(state.params, second, second_end, cut_actor.memory)
    np.testing.assert_allclose(second_out.value[:25], long_out.value[15:40], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(
        second_out.attended_state[:, :25], long_out.attended_state[:, 15:40], rtol=1e-5, atol=1e-6
    )
    np.testing.assert_allclose(first_out.value[:15], long_out.value[:15], rtol=1e-5, atol=1e-6)
    # Eq. 8: the cut is bootstrapped with V(s*_T), the value of the next window's first step.
    np.testing.assert_allclose(first_out.value[15], long_out.value[15], rtol=1e-5, atol=1e-6)
    # Every row's attention sums to one over its own episode.
    np.testing.assert_allclose(np.asarray(second_out.alpha).sum(-1), 1.0, rtol=1e-5)


# ---------------------------------------------------------------------- packed == whole episodes
def whole_episode_layout(traj, limit: int):
    """The complete episodes of a packed window, one per lane, padded to `limit` steps:
    a Trajectory of whole episodes (as SAVN's updates see them) with its WindowEnd (zeros:
    nothing to bootstrap), and the packed window's mask of the steps of complete episodes."""
    done = np.asarray(traj.terminated | traj.truncated)
    step = np.asarray(traj.episode_step)
    T, B = done.shape
    spans = []
    for b in range(B):
        starts = [t for t in range(T) if step[t, b] == 0]
        for start in starts:
            ends = [t for t in range(start, T) if done[t, b]]
            if ends:
                spans.append((b, start, ends[0]))
    complete = np.zeros((T, B), bool)
    for b, start, end in spans:
        complete[start : end + 1, b] = True

    def lay(x):  # [T, B, ...] -> [limit, E, ...], zero padding
        x = np.asarray(x)
        out = np.zeros((limit, len(spans)) + x.shape[2:], x.dtype)
        for e, (b, start, end) in enumerate(spans):
            out[: end + 1 - start, e] = x[start : end + 1, b]
        return out

    valid = lay(complete)
    E = len(spans)
    whole = traj._replace(
        states=lay(traj.states),
        logits=lay(traj.logits),
        actions=lay(traj.actions),
        rewards=lay(traj.rewards),
        terminated=lay(traj.terminated),
        truncated=lay(traj.truncated),
        valid=valid,
        success=lay(traj.success),
        episode_step=np.broadcast_to(np.arange(limit)[:, None], (limit, E)).astype(np.int32),
        s_0=lay(traj.s_0),
        optimal_length=lay(traj.optimal_length),
        room_type=lay(traj.room_type),
        inputs=jax.tree.map(lay, traj.inputs),
    )
    end = WindowEnd(np.zeros((E,) + traj.states.shape[2:], np.float32), np.zeros((E,), np.int32))
    return whole, end, complete


def test_packing_changes_nothing_but_speed(windows):
    """The loss and gradient over the complete episodes of a packed window equal those of
    the same episodes run one per lane, whole."""
    state, (_, long, long_end), _, _ = windows
    packed = H.trainer(PACKED)
    env, env_params = H.bathroom_env()
    whole_trainer = Trainer(H.tiny_config("a3c+foresit", rollout="episodes", num_steps=30), env, env_params)
    whole, whole_end, complete = whole_episode_layout(long, 30)
    assert whole.valid.shape[1] >= 8, "precondition: several complete episodes"
    hidden = PACKED.hidden_size
    E = whole.valid.shape[1]

    def packed_loss(p):
        traj = long._replace(valid=jnp.asarray(complete))
        return packed.window_loss(
            p, replayed(packed.networks, p, traj, state.actor.agent.lstm), long_end, state.actor.memory
        )[0]

    def whole_loss(p):
        zeros = (jnp.zeros((E, hidden)), jnp.zeros((E, hidden)))
        traj = jax.tree.map(jnp.asarray, whole)
        end = jax.tree.map(jnp.asarray, whole_end)
        return whole_trainer.window_loss(
            p, replayed(whole_trainer.networks, p, traj, zeros), end, jnp.zeros((E, 0, hidden))
        )[0]

    grad = functools.partial(jax.jit, compiler_options=H.FAST_COMPILE)
    loss_p, grads_p = grad(jax.value_and_grad(packed_loss))(state.params)
    loss_w, grads_w = grad(jax.value_and_grad(whole_loss))(state.params)
    np.testing.assert_allclose(loss_p, loss_w, rtol=1e-5)
    assert H.max_abs(grads_w) > 0
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-7), grads_p, grads_w)


# ---------------------------------------------------------------------- the bootstrap at a cut
def test_bootstrapped_return_at_a_cut_by_hand():
    """One lane, 4 steps: a successful Done at step 1, then an episode cut by the window's
    end and bootstrapped with V(s*_T) = 2 (gamma 0.99, lambda 1):
      R_3 = -0.01 + 0.99 * 2      = 1.97
      R_2 = -0.01 + 0.99 * 1.97   = 1.9403
      R_1 = 5                      (Done: nothing follows)
      R_0 = -0.01 + 0.99 * 5      = 4.94
    and A_t = R_t - v_t with lambda = 1. Ended by the time limit instead, the last step
    bootstraps nothing: R_3 = -0.01, R_2 = -0.01 - 0.99 * 0.01 = -0.0199."""
    r = jnp.asarray([-0.01, 5.0, -0.01, -0.01])[:, None]
    v = jnp.asarray([0.5, 1.0, 0.2, 0.3])[:, None]
    term = jnp.asarray([0, 1, 0, 0], bool)[:, None]
    valid = jnp.ones((4, 1), bool)
    advantage, returns = train.advantages_and_returns(
        r, v, term, jnp.zeros_like(term), valid, jnp.asarray([2.0]), 0.99, 1.0
    )
    np.testing.assert_allclose(returns[:, 0], [4.94, 5.0, 1.9403, 1.97], rtol=1e-6)
    np.testing.assert_allclose(advantage[:, 0], [4.44, 4.0, 1.7403, 1.67], rtol=1e-5)
    trunc = jnp.asarray([0, 0, 0, 1], bool)[:, None]
    _, returns = train.advantages_and_returns(r, v, term, trunc, valid, jnp.asarray([2.0]), 0.99, 1.0)
    np.testing.assert_allclose(returns[:, 0], [4.94, 5.0, -0.0199, -0.01], rtol=1e-6)


# ---------------------------------------------------------------------- bookkeeping per episode
@pytest.mark.slow
def test_foresit_bookkeeping_fires_once_per_ended_episode_never_for_a_cut_one():
    """Easy bathrooms (random success ~15%), big buffers (no f_w flush): after one update,
    each lane's tracker counts its ended episodes and its buffer its successful ones; the
    episode cut at the window's end counts in neither. The buffer items are the episodes'
    (s_0, g_tau, ŝ_tau), ŝ_tau one of the episode's own states."""
    config = H.tiny_config("a3c+foresit", num_steps=40, num_lanes=8, buffer_size=64)
    env, env_params = H.bathroom_env()
    trainer = Trainer(config, env, H.easy_env_params(env_params))
    state = jax.jit(trainer.init, compiler_options=H.FAST_COMPILE)(jax.random.PRNGKey(0))
    new, metrics = jax.jit(trainer.update, compiler_options=H.FAST_COMPILE)(state, trainer.env_params)
    # The same window again, outside the update (same key, same parameters).
    _, k_act, _ = jax.random.split(state.key, 3)
    _, traj, _ = jax.jit(trainer.act, compiler_options=H.FAST_COMPILE)(
        AgentParams(state.params, state.imagination_params), trainer.bind(trainer.env_params), state.actor, k_act
    )
    done = np.asarray(traj.terminated | traj.truncated)
    success = np.asarray(traj.success)
    ended_per_lane, successes_per_lane = done.sum(0), (success & done).sum(0)
    assert successes_per_lane.sum() >= 2, "precondition: some successes"
    assert (~done[-1]).any(), "precondition: some episode is cut at the window's end"
    np.testing.assert_array_equal(new.actor.agent.imagination.tracker.count, ended_per_lane)
    np.testing.assert_array_equal(new.actor.agent.imagination.tracker.outcomes.sum(-1), successes_per_lane)
    np.testing.assert_array_equal(new.buffers.count, successes_per_lane)
    assert float(metrics["charts/episodes"]) == ended_per_lane.sum()
    np.testing.assert_allclose(
        float(metrics["charts/success_rate"]), successes_per_lane.sum() / ended_per_lane.sum(), rtol=1e-6
    )
    step, states, goals = np.asarray(traj.episode_step), np.asarray(traj.states), np.asarray(traj.inputs.obs["target"])
    for b in range(config.num_lanes):
        items = 0
        for t in np.flatnonzero(success[:, b] & done[:, b]):
            start = t - step[t, b]
            assert start >= 0, "the window began with fresh episodes"
            np.testing.assert_allclose(new.buffers.s_0[b, items], states[start, b], rtol=1e-5, atol=1e-6)
            np.testing.assert_array_equal(new.buffers.goal[b, items], goals[t, b])
            distance = np.abs(states[start : t + 1, b] - np.asarray(new.buffers.subgoal[b, items])).max(-1)
            assert distance.min() < 1e-5, "the sub-goal is one of the episode's own states"
            items += 1
    # The next update ends the cut episodes: each is counted once, in the window it ends in.
    newer, _ = jax.jit(trainer.update, compiler_options=H.FAST_COMPILE)(new, trainer.env_params)
    _, k_act, _ = jax.random.split(new.key, 3)
    _, traj2, _ = jax.jit(trainer.act, compiler_options=H.FAST_COMPILE)(
        AgentParams(new.params, new.imagination_params), trainer.bind(trainer.env_params), new.actor, k_act
    )
    ended_2 = np.asarray(traj2.terminated | traj2.truncated).sum(0)
    np.testing.assert_array_equal(
        newer.actor.agent.imagination.tracker.count, np.minimum(ended_per_lane + ended_2, config.success_window)
    )
