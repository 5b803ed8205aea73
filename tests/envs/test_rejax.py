"""A JAX RL library people use, unmodified, on GridNav's gymnax face: rejax's PPO (rejax
deep-copies its config, reads `env_params.max_steps_in_episode` as its evaluator's loop
bound and unpacks gymnax's five-value step), given the env object and given its registered
name (rejax's string path: `gymnax.make` with `env_params` as keywords). Installed with the
`rejax` extra; skipped with a reason without it."""

import importlib.util
import warnings

import jax
import numpy as np
import pytest

import envs
from envs import gymnax_compat

pytestmark = [
    pytest.mark.slow,  # trains (about 20 s on a 2-core CPU)
    pytest.mark.skipif(
        importlib.util.find_spec("rejax") is None, reason="rejax is not installed (pip install -e '.[rejax]')"
    ),
]


def test_rejax_ppo_trains_on_gridnav_and_its_success_rate_rises():
    from rejax import PPO

    # rejax 0.1.3 unpacks five values (gymnax before 1.0): make_gymnax's step_api="done".
    env, params = envs.make_gymnax("GridNav-v0", step_api="done", room_types=["bathroom"])
    algo = PPO.create(
        env=env,
        env_params=params,
        total_timesteps=200_000,
        eval_freq=50_000,
        num_envs=32,
        num_steps=64,
        num_epochs=4,
        num_minibatches=4,
        learning_rate=1e-3,
        ent_coef=0.01,
        agent_kwargs={"hidden_layer_sizes": (128, 128)},
    )
    _, (lengths, returns) = jax.jit(algo.train)(jax.random.PRNGKey(0))
    returns, lengths = np.asarray(returns), np.asarray(lengths)
    assert returns.shape[0] == 5  # evaluations at 0, 50k, ..., 200k steps, 128 episodes each
    assert (lengths <= params.max_steps_in_episode).all()
    # A return above 0 is a success (+5, less at most 30 step penalties of 0.01); without one
    # it is below 0.
    success = (returns > 0).mean(axis=-1)
    assert success[0] < 0.2, success  # the untrained policy: about the random policy's rate
    assert success[-1] > success[0] + 0.3, success  # measured: 0.05 -> 0.86


def test_rejax_string_path_builds_the_five_value_env_and_trains():
    """`PPO.create(env="GridNav-v0", env_params={...})`: rejax 0.1.3 calls
    `gymnax.make("GridNav-v0", **env_params)` (rejax.compat.create), so after
    `envs.register_gymnax()` it gets make_gymnax's defaults: the five-value step rejax
    unpacks, and no warning.  A few iterations: that it builds and trains, not that it
    learns."""
    from rejax import PPO

    if not envs.register_gymnax():
        pytest.skip("rejax's string path needs gymnax >= 1.0's registry")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        algo = PPO.create(
            env="GridNav-v0",
            env_params={"room_types": ["bathroom"]},
            total_timesteps=4096,
            eval_freq=2048,
            num_envs=16,
            num_steps=64,
            num_epochs=1,
            num_minibatches=4,
            learning_rate=1e-3,
            agent_kwargs={"hidden_layer_sizes": (64, 64)},
        )
    assert not [w for w in caught if "step_api" in str(w.message)], [str(w.message) for w in caught]
    assert isinstance(algo.env, gymnax_compat.GymnaxGridNav) and algo.env.step_api == "done"
    assert algo.env.gridnav.setup == "savn" and algo.env_params.max_steps_in_episode == 30
    assert np.asarray(algo.env_params.bank.room_type).tolist() == [3] * algo.env_params.bank.numbers.shape[0]
    train_state, (lengths, returns) = jax.jit(algo.train)(jax.random.PRNGKey(0))
    returns, lengths = np.asarray(returns), np.asarray(lengths)
    assert returns.shape == lengths.shape == (3, 128)  # evaluations at 0, 2048 and 4096 steps
    assert np.isfinite(returns).all() and ((lengths >= 1) & (lengths <= 30)).all()
    assert int(train_state.global_step) == 4096  # four iterations of 16 envs x 64 steps
    assert all(np.isfinite(np.asarray(leaf)).all() for leaf in jax.tree.leaves(train_state.actor_ts.params))
