"""GridNav's ``info``: ``final_observation`` is optional (constructor argument), everything
else is unchanged by it; per-episode facts (optimal length, room type, scene, target) in
``info`` belong to the episode that was stepped, also on the step that auto-resets."""

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from envs import catalog as C

NUM_ENVS, NUM_STEPS = 32, 70
# Done is frequent so that episodes end (and reset into other room types) often.
ACTION_PROBS = (0.3, 0.2, 0.2, 0.1, 0.1, 0.1)
ROOMS = ("bedroom", "bathroom")


def rollout(env, params, key):
    """lax.scan over a vmapped batch; records the state before each step and the outputs."""

    def run(key):
        k_reset, key = jax.random.split(key)
        _, state = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(k_reset, NUM_ENVS), params)

        def body(carry, _):
            state, key = carry
            key, k_act, k_step = jax.random.split(key, 3)
            action = jax.random.choice(k_act, C.NUM_ACTIONS, (NUM_ENVS,), p=jnp.array(ACTION_PROBS))
            obs, new_state, reward, terminated, truncated, info = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
                jax.random.split(k_step, NUM_ENVS), state, action, params
            )
            return (new_state, key), (state, obs, new_state, reward, terminated, truncated, info)

        return jax.lax.scan(body, (state, key), None, NUM_STEPS)[1]

    return jax.tree.map(np.asarray, jax.jit(run)(key))


@pytest.fixture(scope="module")
def both():
    """The same rollout with and without final_observation (training limits: 30 steps)."""
    with_final, params = envs.make("GridNav-v0", split="val", room_types=ROOMS, view_width=2, training=True)
    without, params_without = envs.make(
        "GridNav-v0", split="val", room_types=ROOMS, view_width=2, training=True, final_observation=False
    )
    assert with_final.final_observation and not without.final_observation
    chex.assert_trees_all_equal(params, params_without)  # the same (lru-cached) bank
    key = jax.random.key(11)
    return with_final, params, rollout(with_final, params, key), rollout(without, params, key)


def test_final_observation_is_optional_and_changes_nothing_else(both):
    env, params, (*outs_with, info_with), (*outs_without, info_without) = both
    assert "final_observation" in info_with and "final_observation" not in info_without
    assert set(info_with) - set(info_without) == {"final_observation"}
    chex.assert_trees_all_equal(outs_with, outs_without)
    chex.assert_trees_all_equal({k: v for k, v in info_with.items() if k != "final_observation"}, info_without)
    # With it: the observation the step reached, which is the returned one unless done.
    _, obs, _, _, terminated, truncated = outs_with
    done = terminated | truncated
    final = info_with["final_observation"]
    assert set(final) == set(env.observation_space(params).spaces)
    for name in final:
        np.testing.assert_array_equal(final[name][~done], obs[name][~done])
    assert done.any() and any((final[n][done] != obs[n][done]).any() for n in final)


def test_info_carries_the_facts_of_the_episode_being_stepped(both):
    """optimal_length, room_type, target and scene in info are those of the state before the
    step (the episode stepped), also when the step ends it and resets into another one."""
    _, params, (state_before, _, state_after, _, terminated, truncated, info), _ = both
    done = terminated | truncated
    numbers = np.asarray(params.bank.numbers)
    np.testing.assert_array_equal(info["optimal_length"], state_before.optimal_length)
    np.testing.assert_array_equal(info["room_type"], state_before.room_type)
    np.testing.assert_array_equal(info["target"], state_before.target)
    np.testing.assert_array_equal(info["scene"], numbers[state_before.scene])
    np.testing.assert_array_equal(info["episode_length"], state_before.time + 1)
    # The reset really moves on: on done steps the returned state is often another room type.
    assert done.sum() > NUM_ENVS
    assert (state_after.room_type[done] != info["room_type"][done]).any()
    assert (state_after.time[done] == 0).all()
