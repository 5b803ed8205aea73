"""foresit_jax.train.replayed: the replay gradient (re-running the modules over a window's
recorded inputs, the feed-forward part batched over the whole window) against the
reference, differentiating through the acting scan; on a window that starts in the
middle of episodes (carried LSTM state and critic memory), holds several episodes and
ends with a cut. Also the recomputed values against the acting pass's."""

import dataclasses
import functools

import jax
import numpy as np
import pytest

import train_helpers as H
from foresit_jax.rollout import AgentParams
from foresit_jax.train import replayed
from foresit_jax.train import Trainer

REPLAY = H.tiny_config("a3c+foresit", num_steps=20, num_lanes=4)
THROUGH = dataclasses.replace(REPLAY, gradient="through_rollout")


@functools.lru_cache(maxsize=None)
def _grads(config):
    trainer = H.trainer(config)

    def grads(state):
        (loss, aux), g = trainer.loss_and_grad(
            state.params, state.imagination_params, trainer.bind(trainer.env_params), state.actor, state.key
        )
        return loss, aux[1], g

    return jax.jit(grads, compiler_options=H.FAST_COMPILE)


@pytest.fixture(scope="module")
def mid_episode_state():
    """The tiny state after one update: lanes are in the middle of episodes."""
    state = H.jitted_init(REPLAY)(jax.random.PRNGKey(0))
    state, _ = H.jitted_update(REPLAY)(state, H.trainer(REPLAY).env_params)
    assert (np.asarray(state.actor.agent.episode_step) > 0).any(), "precondition: a window starting mid-episode"
    return state


@pytest.mark.parametrize(
    "method, reading",
    [
        ("a3c+foresit", "head"),
        *(
            pytest.param(*case, marks=pytest.mark.slow)
            for case in (("a3c", "head"), ("a3c+foresit", "encoder"), ("a3c+foresit", "mlp"))
        ),
    ],
)
def test_replay_gradient_equals_differentiating_through_the_rollout(method, reading, mid_episode_state):
    replay_config = dataclasses.replace(REPLAY, method=method, imagination_input=reading)
    through_config = dataclasses.replace(THROUGH, method=method, imagination_input=reading)
    state = mid_episode_state
    if replay_config != REPLAY:  # same lanes and keys, this method's parameters
        fresh = H.jitted_init(replay_config)(jax.random.PRNGKey(0))
        fresh, _ = H.jitted_update(replay_config)(fresh, H.trainer(replay_config).env_params)
        state = fresh
    loss_r, traj_r, g_replay = _grads(replay_config)(state)
    loss_t, traj_t, g_through = _grads(through_config)(state)
    np.testing.assert_array_equal(traj_r.actions, traj_t.actions)
    assert (np.asarray(traj_r.episode_step) == 0).sum() >= 4, "precondition: episodes begin inside the window"
    np.testing.assert_allclose(loss_r, loss_t, rtol=1e-5)
    assert H.max_abs(g_through) > 0
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-7), g_replay, g_through)


def test_replay_recomputes_the_acting_values(mid_episode_state):
    """Same values as acting, up to float rounding (the encoder runs batched over the
    window instead of one step at a time)."""
    state = mid_episode_state
    trainer = H.trainer(REPLAY)
    act = jax.jit(trainer.act, compiler_options=H.FAST_COMPILE)
    _, traj, _ = act(
        AgentParams(state.params, state.imagination_params), trainer.bind(trainer.env_params), state.actor, state.key
    )
    again = jax.jit(functools.partial(replayed, trainer.networks), compiler_options=H.FAST_COMPILE)(
        state.params, traj, state.actor.agent.lstm
    )
    np.testing.assert_allclose(again.states, traj.states, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(again.logits, traj.logits, rtol=1e-5, atol=1e-6)


def test_replay_needs_recorded_inputs(mid_episode_state):
    trainer = H.trainer(REPLAY)
    state = mid_episode_state
    _, traj, _ = jax.jit(trainer.act, compiler_options=H.FAST_COMPILE)(
        AgentParams(state.params, state.imagination_params), trainer.bind(trainer.env_params), state.actor, state.key
    )
    with pytest.raises(ValueError, match="record_inputs"):
        replayed(trainer.networks, state.params, traj._replace(inputs=None), state.actor.agent.lstm)


def test_whole_episode_rollout_needs_room_for_an_episode():
    env, env_params = H.bathroom_env()
    with pytest.raises(ValueError, match="num_steps"):
        Trainer(H.tiny_config(rollout="episodes", num_steps=29), env, env_params)
    Trainer(H.tiny_config(rollout="packed", num_steps=8), env, env_params)  # windows may be shorter
