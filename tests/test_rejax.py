"""A JAX RL library people use, unmodified, on GridNav's gymnax face: rejax's PPO (rejax
deep-copies its config, reads `env_params.max_steps_in_episode` as its evaluator's loop
bound and unpacks gymnax's five-value step). Installed with the `rejax` extra; skipped with
a reason without it."""

import importlib.util

import jax
import numpy as np
import pytest

import envs

pytestmark = [
    pytest.mark.slow,  # trains (about 20 s on a 2-core CPU)
    pytest.mark.skipif(importlib.util.find_spec("rejax") is None,
                       reason="rejax is not installed (pip install -e '.[rejax]')"),
]


def test_rejax_ppo_trains_on_gridnav_and_its_success_rate_rises():
    from rejax import PPO

    # rejax 0.1.3 unpacks five values (gymnax before 1.0): make_gymnax's step_api="done".
    env, params = envs.make_gymnax("GridNav-v0", step_api="done", room_types=["bathroom"])
    algo = PPO.create(env=env, env_params=params, total_timesteps=200_000, eval_freq=50_000, num_envs=32,
                      num_steps=64, num_epochs=4, num_minibatches=4, learning_rate=1e-3, ent_coef=0.01,
                      agent_kwargs={"hidden_layer_sizes": (128, 128)})
    _, (lengths, returns) = jax.jit(algo.train)(jax.random.PRNGKey(0))
    returns, lengths = np.asarray(returns), np.asarray(lengths)
    assert returns.shape[0] == 5  # evaluations at 0, 50k, ..., 200k steps, 128 episodes each
    assert (lengths <= params.max_steps_in_episode).all()
    # A return above 0 is a success (+5, less at most 30 step penalties of 0.01); without one
    # it is below 0.
    success = (returns > 0).mean(axis=-1)
    assert success[0] < 0.2, success  # the untrained policy: about the random policy's rate
    assert success[-1] > success[0] + 0.3, success  # measured: 0.05 -> 0.86
