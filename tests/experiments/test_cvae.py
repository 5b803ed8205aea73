"""The C-VAE of the paper's imagination comparison: its KL against the textbook formula
and a Monte Carlo estimate, the reparameterised gradient, learning on data with a known
conditional structure, and the comparison itself on such data."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from experiments.analysis import cvae
from foresit_jax import imagination


def synthetic_items(key, n, state=12, goal_size=4):
    """ŝ = tanh(A s_0 + B g) + small noise: a sub-goal that the condition determines."""
    k = jax.random.split(key, 5)
    s_0 = jnp.tanh(jax.random.normal(k[0], (n, state)))
    goal = jax.random.normal(k[1], (n, goal_size))
    a = jax.random.normal(k[2], (state, state)) / np.sqrt(state)
    b = jax.random.normal(k[3], (goal_size, state)) / np.sqrt(goal_size)
    subgoal = jnp.tanh(s_0 @ a + goal @ b) + 0.02 * jax.random.normal(k[4], (n, state))
    return s_0, goal, subgoal


def test_kl_matches_the_two_normals_formula_and_a_monte_carlo_estimate():
    mu = np.array([[0.3, -1.2, 0.0], [2.0, 0.1, -0.4]])
    log_var = np.array([[0.0, -0.7, 1.1], [0.5, -2.0, 0.2]])
    sigma = np.exp(0.5 * log_var)
    # KL(N(m, s^2) || N(0, 1)) = -log s + (s^2 + m^2) / 2 - 1/2, per unit, summed.
    textbook = np.sum(-np.log(sigma) + (sigma**2 + mu**2) / 2 - 0.5, axis=-1)
    np.testing.assert_allclose(cvae.gaussian_kl(jnp.asarray(mu), jnp.asarray(log_var)), textbook, rtol=1e-6)
    rng = np.random.default_rng(0)
    z = mu + sigma * rng.standard_normal((200_000, *mu.shape))
    log_q = -0.5 * (((z - mu) / sigma) ** 2) - np.log(sigma)
    log_p = -0.5 * z**2
    np.testing.assert_allclose(np.mean(np.sum(log_q - log_p, axis=-1), axis=0), textbook, rtol=0.02, atol=0.01)


def test_the_loss_reaches_the_encoder_through_the_sample_and_the_condition_shapes_the_decoder():
    s_0, goal, subgoal = synthetic_items(jax.random.PRNGKey(0), 8)
    model = cvae.CVAE(state_size=12, latent_size=5, hidden_size=16)
    params = model.init(jax.random.PRNGKey(1), subgoal, s_0, goal, jax.random.PRNGKey(2))
    mu, log_var = model.apply(params, subgoal, s_0, goal, method=cvae.CVAE.encode)
    assert mu.shape == log_var.shape == (8, 5)
    # Without the KL term the encoder's mean head gets its gradient only through z.
    grads = jax.grad(lambda p: cvae.cvae_loss(model, p, subgoal, s_0, goal, jax.random.PRNGKey(3), beta=0.0)[0])(params)
    assert float(jnp.abs(grads["params"]["enc_mu"]["kernel"]).sum()) > 0
    z = jnp.zeros((8, 5))
    other = model.apply(params, z, s_0[::-1], goal[::-1], method=cvae.CVAE.decode)
    assert not np.allclose(model.apply(params, z, s_0, goal, method=cvae.CVAE.decode), other)


@pytest.mark.slow  # trains for 40 epochs, 5.6 s cold (docs/testing.md)
def test_the_cvae_learns_a_conditional_structure():
    s_0, goal, subgoal = synthetic_items(jax.random.PRNGKey(0), 1024)
    model = cvae.CVAE(state_size=12, latent_size=4, hidden_size=64)
    params, step_losses = jax.jit(lambda k: cvae.fit_cvae(model, k, subgoal, s_0, goal, epochs=40))(
        jax.random.PRNGKey(1)
    )
    assert np.all(np.isfinite(step_losses))
    _, (reconstruction, kl) = cvae.cvae_loss(model, params, subgoal, s_0, goal, jax.random.PRNGKey(2))
    total_variance = float(jnp.sum(jnp.var(subgoal, axis=0)))  # what predicting the mean would cost
    assert float(reconstruction) < 0.2 * total_variance, (float(reconstruction), total_variance)
    assert float(step_losses[-20:].mean()) < 0.5 * float(step_losses[:20].mean())


@pytest.mark.slow
def test_the_comparison_trains_both_imaginations_and_beats_predicting_the_mean():
    items = synthetic_items(jax.random.PRNGKey(0), 768)
    train = jax.tree.map(lambda x: x[:512], items)
    test = jax.tree.map(lambda x: x[512:], items)
    out = cvae.compare_imagination_targets(
        jax.random.PRNGKey(1), train, test, layer_sizes=(32, 8, 32, 12), latent_size=4, epochs=40
    )
    assert set(out) == {"cvae_final_loss", "cvae_reconstruction", "cvae_kl", "direct", "cvae_latent"}
    assert out["cvae_kl"] >= 0 and out["direct"]["loss_over_variance"] == pytest.approx(
        out["direct"]["loss"] / out["direct"]["target_variance"], rel=1e-5
    )
    mean_guess = imagination.imagination_loss(
        lambda p, s, g: jnp.broadcast_to(p, (s.shape[0], 12)), jnp.mean(train[2], axis=0), test[0], test[1], test[2]
    )
    assert 0 < out["direct"]["loss"] < 0.5 * float(mean_guess)
    assert np.isfinite(out["cvae_latent"]["loss"]) and out["cvae_latent"]["target_variance"] > 0
    assert out["direct"]["target_variance"] == pytest.approx(float(jnp.mean(jnp.var(test[2], axis=0))))
    assert float(imagination.smooth_l1(test[2], test[2]).mean()) == 0.0
