"""foresit_jax.distributions against numpy references."""

import chex
import jax
import jax.numpy as jnp
import numpy as np

from foresit_jax import distributions


def np_log_softmax(logits):
    logits = np.asarray(logits, np.float64)
    shifted = logits - logits.max(-1, keepdims=True)
    return shifted - np.log(np.exp(shifted).sum(-1, keepdims=True))


class CategoricalTest(chex.TestCase):
    def setUp(self):
        super().setUp()
        rng = np.random.default_rng(0)
        self.logits = rng.normal(size=(4, 5, 6)).astype(np.float32) * 3.0  # [B, T, A]
        self.actions = rng.integers(0, 6, size=(4, 5))  # [B, T]

    @chex.variants(with_jit=True, without_jit=True)
    def test_log_prob_matches_numpy(self):
        out = self.variant(distributions.log_prob)(self.logits, self.actions)
        chex.assert_shape(out, (4, 5))
        expected = np.take_along_axis(np_log_softmax(self.logits), self.actions[..., None], -1)[..., 0]
        np.testing.assert_allclose(out, expected, rtol=1e-5, atol=1e-5)

    @chex.variants(with_jit=True, without_jit=True)
    def test_entropy_matches_numpy(self):
        out = self.variant(distributions.entropy)(self.logits)
        chex.assert_shape(out, (4, 5))
        logp = np_log_softmax(self.logits)
        np.testing.assert_allclose(out, -(np.exp(logp) * logp).sum(-1), rtol=1e-5, atol=1e-6)

    def test_entropy_extremes(self):
        np.testing.assert_allclose(distributions.entropy(jnp.zeros(6)), np.log(6.0), rtol=1e-6)
        peaked = jnp.array([100.0, 0, 0, 0, 0, 0])
        np.testing.assert_allclose(distributions.entropy(peaked), 0.0, atol=1e-6)

    def test_stable_for_huge_logits(self):
        logits = jnp.array([1000.0, 999.0, -1000.0])
        out = distributions.log_prob(logits, jnp.array(1))
        np.testing.assert_allclose(out, np_log_softmax([1000.0, 999.0, -1000.0])[1], rtol=1e-6)
        self.assertTrue(np.isfinite(distributions.entropy(logits)))

    def test_probs_sum_to_one_and_match_softmax(self):
        p = distributions.probs(self.logits)
        np.testing.assert_allclose(p, np.exp(np_log_softmax(self.logits)), rtol=1e-5, atol=1e-7)
        np.testing.assert_allclose(p.sum(-1), 1.0, rtol=1e-6)

    def test_log_prob_gradient_is_onehot_minus_probs(self):
        logits, action = jnp.asarray(self.logits[0, 0]), 2
        grad = jax.grad(distributions.log_prob)(logits, jnp.array(action))
        expected = np.eye(6)[action] - np.exp(np_log_softmax(self.logits[0, 0]))
        np.testing.assert_allclose(grad, expected, rtol=1e-5, atol=1e-6)

    @chex.variants(with_jit=True, without_jit=True)
    def test_sample_frequencies_match_probs(self):
        logits = jnp.array([[0.0, 1.0, 2.0, -1.0], [3.0, 0.0, 0.0, 0.0]])  # [2, A]
        n = 20000
        batch = jnp.broadcast_to(logits, (n, 2, 4))
        samples = self.variant(distributions.sample)(jax.random.key(1), batch)
        chex.assert_shape(samples, (n, 2))
        self.assertEqual(samples.dtype, jnp.int32)
        for row in range(2):
            freq = np.bincount(np.asarray(samples[:, row]), minlength=4) / n
            expected = np.exp(np_log_softmax(logits[row]))
            # 4 sigma of a binomial proportion with n=20000 is < 0.015.
            np.testing.assert_allclose(freq, expected, atol=0.015)

    def test_sample_depends_on_key_and_is_reproducible(self):
        logits = jnp.zeros((1000, 6))
        a = distributions.sample(jax.random.key(0), logits)
        b = distributions.sample(jax.random.key(0), logits)
        c = distributions.sample(jax.random.key(1), logits)
        np.testing.assert_array_equal(a, b)
        self.assertFalse(np.array_equal(a, c))

    def test_greedy(self):
        np.testing.assert_array_equal(distributions.greedy(self.logits), self.logits.argmax(-1))
