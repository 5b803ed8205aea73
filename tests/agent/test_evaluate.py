"""foresit_jax.evaluate: SR/SPL summaries against hand-computed values, the evaluation
noise variance, evaluate() over the validation split, the random-policy rollout against an
independent per-episode record, and an Evaluator that compiles once."""

import math

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import train_helpers as H
from envs import metrics
from experiments.running.presets import preset
from foresit_jax import imagination
from foresit_jax.rollout import EpisodeStats
from foresit_jax.evaluate import (
    Evaluator,
    agent_params,
    evaluate,
    evaluate_random_policy,
    outcome_metrics,
    random_policy_rollout,
    summarize,
)

KEYS = {"SR", "SPL", "SR>=5", "SPL>=5", "episodes", "episodes>=5"}


def test_summarize_hand_computed():
    success = [1, 0, 1, 1, 0]
    optimal = [2, 6, 5, 3, 9]
    lengths = [4, 30, 5, 3, 12]
    # SPL_i = s_i * L^g_i / max(L_i, L^g_i)
    spl = [s * g / max(n, g) for s, g, n in zip(success, optimal, lengths)]  # .5, 0, 1, 1, 0
    got = summarize(success, spl, optimal)
    assert got == pytest.approx(
        {
            "SR": 60.0,
            "SPL": 50.0,  # (.5 + 0 + 1 + 1 + 0) / 5
            "SR>=5": 100 / 3,
            "SPL>=5": 100 / 3,  # episodes 1, 2, 4 have L^g >= 5
            "episodes": 5,
            "episodes>=5": 3,
        }
    )
    # L^g = 5 is in the bucket, 4 is not.
    assert summarize([1, 1], [1.0, 1.0], [4, 5])["episodes>=5"] == 1


def test_summarize_empty_long_bucket_is_nan():
    got = summarize([1, 0], [0.5, 0.0], [2, 4])
    assert got["SR"] == 50.0 and got["SPL"] == 25.0 and got["episodes>=5"] == 0
    assert math.isnan(got["SR>=5"]) and math.isnan(got["SPL>=5"])


def test_agent_params_noise_variance_is_the_lanes_mean_of_eq7():
    state = H.jitted_init(H.tiny_config())(jax.random.PRNGKey(0))
    tracker = imagination.tracker_init(4)
    rates = [0.0, 0.25, 1.0, 0.5]  # rho per lane -> sigma^2 = max(0.9 - rho, 0)
    lanes = []
    for rho in rates:
        t = tracker
        for i in range(4):
            t = imagination.tracker_update(t, jnp.asarray(i < 4 * rho))
        lanes.append(t)
    trackers = jax.tree.map(lambda *x: jnp.stack(x), *lanes)
    agent = state.actor.agent
    agent = agent._replace(imagination=agent.imagination._replace(tracker=trackers))
    got = agent_params(state._replace(actor=state.actor._replace(agent=agent)), sigma2_max=0.9)
    np.testing.assert_allclose(float(got.noise_variance), np.mean([0.9, 0.65, 0.0, 0.4]), rtol=1e-6)
    assert got.params is state.params and got.imagination_params is state.imagination_params


@pytest.fixture(scope="module")
def tiny_agent():
    """The tiny preset's ForeSIT config on bathrooms (the config the experiments tests
    train, so the compiled evaluation is shared) and freshly initialised agent parameters."""
    with pytest.MonkeyPatch.context() as mp:
        H.patch_for_experiments(mp)
        config, _ = preset("tiny", "a3c+foresit")
        state = jax.jit(H.cached_trainer(config).init, compiler_options=H.FAST_COMPILE)(jax.random.PRNGKey(0))
        yield config, agent_params(state, config.sigma2_max)


def test_evaluate_on_the_validation_split(tiny_agent):
    config, params = tiny_agent
    results = evaluate(params, config, "val", jax.random.PRNGKey(0), episodes_per_room=2)
    assert set(results) == {"bathroom", "overall"}
    for room in results.values():
        assert set(room) == KEYS
        assert room["episodes"] == 2
        assert 0.0 <= room["SPL"] <= room["SR"] <= 100.0
    np.testing.assert_equal(results["overall"], results["bathroom"])  # (NaN == NaN here)
    # Same key, same episodes.
    np.testing.assert_equal(evaluate(params, config, "val", jax.random.PRNGKey(0), episodes_per_room=2), results)


@pytest.mark.slow  # a second evaluation program (14 s cold); the sampled one is tested above
def test_evaluate_greedy_has_the_same_layout(tiny_agent):
    config, params = tiny_agent
    results = evaluate(params, config, "val", jax.random.PRNGKey(0), episodes_per_room=2, greedy=True)
    assert set(results) == {"bathroom", "overall"}
    assert all(set(m) == KEYS and m["episodes"] == 2 for m in results.values())


def test_evaluate_rejects_bad_arguments(tiny_agent):
    config, params = tiny_agent
    with pytest.raises(ValueError, match="split"):
        evaluate(params, config, "holdout")
    with pytest.raises(ValueError, match="episodes_per_room"):
        evaluate(params, config, "val", episodes_per_room=0)


def test_summarize_is_the_one_in_envs_metrics():
    assert summarize is metrics.summarize
    outcomes = EpisodeStats(
        np.array([1, 0, 1, 1, 0], bool), np.array([4, 30, 5, 3, 12]), np.array([2, 6, 5, 3, 9]), np.ones(5, bool)
    )
    assert outcome_metrics(outcomes) == pytest.approx(
        summarize(outcomes.success, [0.5, 0, 1, 1, 0], outcomes.optimal_length)
    )


# ---------------------------------------------------------------------- the random policy
def recorded_random_episodes(env, env_params, key, episodes, num_steps):
    """Reference: the same random actions on the same keys, each lane's first episode read
    from `info` at the step that ends it (the bookkeeping experiments.demo used)."""
    k_reset, k_steps = jax.random.split(key)
    _, state = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(k_reset, episodes), env_params)
    record = {k: np.zeros(episodes, int) for k in ("success", "length", "optimal_length")}
    active = np.ones(episodes, bool)
    step = jax.jit(jax.vmap(env.step, in_axes=(0, 0, 0, None)))
    for key_t in jax.random.split(k_steps, num_steps):
        k_act, k_env = jax.random.split(key_t)
        action = jax.random.randint(k_act, (episodes,), 0, env.num_actions)
        _, state, _, terminated, truncated, info = step(jax.random.split(k_env, episodes), state, action, env_params)
        ending = active & np.asarray(terminated | truncated)
        for k, name in (("success", "success"), ("length", "episode_length"), ("optimal_length", "optimal_length")):
            record[k] = np.where(ending, np.asarray(info[name]), record[k])
        active &= ~ending
    return record, ~active


@pytest.mark.parametrize("num_steps", [6, pytest.param(100, marks=pytest.mark.slow)])  # 100: 7.5 s cold
def test_random_policy_rollout_matches_a_per_episode_record(num_steps):
    env, env_params = H.bathroom_env("val", training=False)
    key, episodes = jax.random.PRNGKey(7), 128
    got = jax.tree.map(
        np.asarray, jax.jit(random_policy_rollout, static_argnums=(0, 3, 4))(env, env_params, key, episodes, num_steps)
    )
    chex.assert_shape(list(got), (episodes,))
    record, ended = recorded_random_episodes(env, env_params, key, episodes, num_steps)
    np.testing.assert_array_equal(got.ended, ended)
    for name in ("success", "length", "optimal_length"):
        np.testing.assert_array_equal(getattr(got, name)[ended], record[name][ended], err_msg=name)
    # Invariants: every episode acts at least once and at most num_steps times; an
    # unfinished one acted every step and did not succeed; success needs L >= L^g >= 1.
    assert (got.length >= 1).all() and (got.length <= num_steps).all() and (got.optimal_length >= 1).all()
    assert (got.length[~got.ended] == num_steps).all() and not got.success[~got.ended].any()
    assert (got.length[got.success] >= got.optimal_length[got.success]).all()
    if num_steps == 100:  # the evaluation time limit: every episode ends
        assert got.ended.all()
        assert got.success.any() and not got.success.all()  # (about 8% of random episodes succeed)


def test_random_policy_rollout_reproduces_with_a_key():
    env, env_params = H.bathroom_env("val", training=False)
    run = jax.jit(lambda k: random_policy_rollout(env, env_params, k, 8, 10))
    chex.assert_trees_all_equal(run(jax.random.PRNGKey(1)), run(jax.random.PRNGKey(1)))


# ---------------------------------------------------------------------- Evaluator
def test_an_evaluator_compiles_once_for_repeated_validation(tiny_agent):
    config, params = tiny_agent
    evaluator = Evaluator(config.setup)
    first = evaluator.evaluate(params, config, "val", jax.random.PRNGKey(0), episodes_per_room=2)
    compiled = dict(evaluator.compiled)
    assert len(compiled) == 1
    second = evaluator.evaluate(params, config, "val", jax.random.PRNGKey(1), episodes_per_room=2)
    assert evaluator.compiled == compiled  # the same jitted rollout ...
    assert next(iter(compiled.values()))._cache_size() == 1  # ... traced and compiled once
    assert set(first) == set(second) == {"bathroom", "overall"}
    # The same results as a fresh Evaluator (what `evaluate` makes without `evaluator=`).
    np.testing.assert_equal(evaluate(params, config, "val", jax.random.PRNGKey(1), 2, evaluator=evaluator), second)
    evaluator.clear()
    assert not evaluator.compiled and not evaluator.params


def test_evaluate_random_policy_pools_the_rooms(tiny_agent):
    config, _ = tiny_agent
    evaluator = Evaluator(config.setup)
    results = evaluate_random_policy(config, "val", jax.random.PRNGKey(0), episodes_per_room=16, evaluator=evaluator)
    assert set(results) == {"bathroom", "overall"}
    np.testing.assert_equal(results["overall"], results["bathroom"])  # (NaN == NaN here)
    assert results["overall"]["episodes"] == 16 and 0.0 <= results["overall"]["SPL"] <= results["overall"]["SR"]


def test_an_evaluator_refuses_a_config_of_another_setup(tiny_agent):
    config, params = tiny_agent
    with pytest.raises(ValueError, match="setup 'org'"):
        Evaluator("org").evaluate(params, config, "val", episodes_per_room=1)
