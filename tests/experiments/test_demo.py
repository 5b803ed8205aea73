"""experiments.demo: the oracle plays the random policy's episodes, every one a success."""

import jax
import numpy as np
import pytest

import train_helpers as H


# Cheap in-process CLI calls for every test of this module (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("cheap_experiments")


@pytest.mark.slow
def test_demo_oracle_plays_the_random_policys_episodes():
    from experiments import demo
    from foresit_jax.evaluate import random_policy_rollout

    env, env_params = H.bathroom_env("test", training=False)
    key = jax.random.PRNGKey(5)
    random = random_policy_rollout(env, env_params, key, 6, 100)
    _, _, oracle, _ = demo.oracle_rollout(env, 6, 100)(env_params, key)
    np.testing.assert_array_equal(random.optimal_length, oracle.optimal_length)  # the same episodes
    assert np.asarray(oracle.success).all() and (np.asarray(oracle.length) == np.asarray(oracle.optimal_length)).all()
    m = demo.metrics(jax.tree.map(np.asarray, oracle))
    assert m["SR"] == m["SPL"] == 100.0 and m["episodes"] == 6
