"""foresit_jax.evaluate: SR/SPL summaries against hand-computed values, the evaluation
noise variance, and evaluate() over the validation split."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import train_helpers as H
from experiments.presets import preset
from foresit_jax import imagination
from foresit_jax.evaluate import agent_params, evaluate, summarize

KEYS = {"SR", "SPL", "SR>=5", "SPL>=5", "episodes", "episodes>=5"}


def test_summarize_hand_computed():
    success = [1, 0, 1, 1, 0]
    optimal = [2, 6, 5, 3, 9]
    lengths = [4, 30, 5, 3, 12]
    # SPL_i = s_i * L^g_i / max(L_i, L^g_i)
    spl = [s * g / max(n, g) for s, g, n in zip(success, optimal, lengths)]  # .5, 0, 1, 1, 0
    got = summarize(success, spl, optimal)
    assert got == pytest.approx({
        "SR": 60.0, "SPL": 50.0,  # (.5 + 0 + 1 + 1 + 0) / 5
        "SR>=5": 100 / 3, "SPL>=5": 100 / 3,  # episodes 1, 2, 4 have L^g >= 5
        "episodes": 5, "episodes>=5": 3,
    })  # fmt: skip
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
    got = agent_params(state._replace(actor=state.actor._replace(tracker=trackers)), sigma2_max=0.9)
    np.testing.assert_allclose(float(got.noise_variance), np.mean([0.9, 0.65, 0.0, 0.4]), rtol=1e-6)
    assert got.params is state.params and got.imagination_params is state.imagination_params


@pytest.fixture(scope="module")
def tiny_agent():
    """The tiny preset's ForeSIT config on bathrooms (the config the experiments tests
    train, so the compiled evaluation is shared) and freshly initialised agent parameters."""
    with pytest.MonkeyPatch.context() as mp:
        H.patch_for_experiments(mp)
        config, _ = preset("tiny", "a3c+foresit")
        state = H.cached_trainer(config).init(jax.random.PRNGKey(0))
        yield config, agent_params(state, config.sigma2_max)


def test_evaluate_on_the_validation_split(tiny_agent):
    config, params = tiny_agent
    results = evaluate(params, config, "val", jax.random.PRNGKey(0), episodes_per_room=2)
    assert set(results) == {"bathroom", "overall"}
    for metrics in results.values():
        assert set(metrics) == KEYS
        assert metrics["episodes"] == 2
        assert 0.0 <= metrics["SPL"] <= metrics["SR"] <= 100.0
    np.testing.assert_equal(results["overall"], results["bathroom"])  # (NaN == NaN here)
    # Same key, same episodes.
    np.testing.assert_equal(evaluate(params, config, "val", jax.random.PRNGKey(0), episodes_per_room=2), results)


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
