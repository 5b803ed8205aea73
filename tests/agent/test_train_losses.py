"""The losses (foresit_jax.train: returns, advantages, Eq. 8-9; foresit_jax.imagination.smooth_l1) against brute-force loops and hand-computed values."""

import chex
import hypothesis.strategies as st
import jax
import jax.numpy as jnp
import numpy as np
from absl.testing import parameterized
from hypothesis import given, settings

from foresit_jax import imagination, train


def savn_style_targets(r, v, terminated, truncated, valid, bootstrap, gamma, lam):
    """Reference: SAVN's a3c_loss recursion, one lane and one episode at a time.

    r, v, ... are [T, B] numpy arrays. For each lane, the episode is its valid prefix;
    R starts at 0 if the episode ended (Done or time limit) else at the bootstrap value.
    """
    T, B = r.shape
    adv, ret = np.zeros((T, B)), np.zeros((T, B))
    for b in range(B):
        length = int(valid[:, b].sum())
        ended = length > 0 and (terminated[length - 1, b] or truncated[length - 1, b])
        R = 0.0 if ended else float(bootstrap[b])
        if length < T and not ended:
            R = 0.0  # followed by padding: nothing to bootstrap from
        values = list(v[:length, b]) + [R]
        gae = 0.0
        for i in reversed(range(length)):
            R = gamma * R + r[i, b]
            ret[i, b] = R
            delta = r[i, b] + gamma * values[i + 1] - values[i]
            gae = gae * gamma * lam + delta
            adv[i, b] = gae
    return adv, ret


def make_batch(seed, T=7):
    """Four lanes: Done mid-rollout, time limit at the last step, still running at the
    end (bootstrap), Done at step 0. Padding carries garbage values."""
    rng = np.random.default_rng(seed)
    B = 4
    lengths = [4, T, T, 1]
    terminated = np.zeros((T, B), bool)
    truncated = np.zeros((T, B), bool)
    terminated[3, 0] = True
    truncated[T - 1, 1] = True
    terminated[0, 3] = True
    valid = np.arange(T)[:, None] < np.array(lengths)[None]
    r = np.where(rng.random((T, B)) < 0.5, -0.01, 5.0)
    r = np.where(valid, r, rng.normal(size=(T, B)) * 100)  # garbage in padding
    v = rng.normal(size=(T, B))
    v = np.where(valid, v, rng.normal(size=(T, B)) * 100)
    # garbage done flags in the padding must not matter either
    terminated |= (~valid) & (rng.random((T, B)) < 0.5)
    bootstrap = rng.normal(size=(B,))
    return dict(
        r_t=r.astype(np.float32),
        v_t=v.astype(np.float32),
        terminated_t=terminated,
        truncated_t=truncated,
        valid_t=valid,
        bootstrap_value=bootstrap.astype(np.float32),
    )


class TargetsTest(chex.TestCase):
    @chex.variants(with_jit=True, without_jit=True)
    @parameterized.parameters((0.99, 1.0), (0.9, 0.95), (0.5, 0.0))
    def test_matches_episode_loop(self, gamma, lam):
        batch = make_batch(0)
        fn = self.variant(lambda b: train.advantages_and_returns(**b, gamma=gamma, lambda_=lam))
        adv, ret = fn(batch)
        chex.assert_shape([adv, ret], (7, 4))
        exp_adv, exp_ret = savn_style_targets(
            batch["r_t"],
            batch["v_t"],
            batch["terminated_t"],
            batch["truncated_t"],
            batch["valid_t"],
            batch["bootstrap_value"],
            gamma,
            lam,
        )
        np.testing.assert_allclose(adv, exp_adv, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(ret, exp_ret, rtol=1e-5, atol=1e-5)

    def test_hand_computed_done(self):
        # gamma 0.5: rewards -1, -1, 5 then Done; one padding step.
        r = jnp.array([-1.0, -1.0, 5.0, 7.0])
        v = jnp.array([1.0, 2.0, 3.0, 9.0])
        term = jnp.array([0, 0, 1, 0])
        valid = jnp.array([1, 1, 1, 0])
        adv, ret = train.advantages_and_returns(
            r, v, term, jnp.zeros(4), valid, jnp.array(11.0), gamma=0.5, lambda_=1.0
        )
        # R2 = 5, R1 = -1 + 0.5 * 5 = 1.5, R0 = -1 + 0.5 * 1.5 = -0.25
        np.testing.assert_allclose(ret, [-0.25, 1.5, 5.0, 0.0])
        np.testing.assert_allclose(adv, [-1.25, -0.5, 2.0, 0.0])  # R - v (lambda 1)

    def test_time_limit_bootstraps_nothing(self):
        r = jnp.array([-0.01, -0.01, -0.01])
        v = jnp.array([0.3, 0.2, 0.1])
        valid = jnp.ones(3)
        kwargs = dict(gamma=0.99, lambda_=1.0)
        truncated = jnp.array([0, 0, 1])
        _, ret_trunc = train.advantages_and_returns(r, v, jnp.zeros(3), truncated, valid, jnp.array(100.0), **kwargs)
        _, ret_term = train.advantages_and_returns(r, v, truncated, jnp.zeros(3), valid, jnp.array(100.0), **kwargs)
        _, ret_running = train.advantages_and_returns(
            r, v, jnp.zeros(3), jnp.zeros(3), valid, jnp.array(100.0), **kwargs
        )
        expected = [-0.01 * (1 + 0.99 + 0.99**2), -0.01 * 1.99, -0.01]
        np.testing.assert_allclose(ret_trunc, expected, rtol=1e-6)
        np.testing.assert_allclose(ret_term, expected, rtol=1e-6)
        # Still running at the rollout end: the bootstrap value enters.
        np.testing.assert_allclose(ret_running[-1], -0.01 + 0.99 * 100.0, rtol=1e-6)

    def test_padding_garbage_is_ignored(self):
        batch = make_batch(1)
        adv, ret = train.advantages_and_returns(**batch, gamma=0.99, lambda_=1.0)
        rng = np.random.default_rng(5)
        pad = ~batch["valid_t"]
        noisy = dict(batch)
        noisy["r_t"] = np.where(pad, rng.normal(size=pad.shape) * 1e3, batch["r_t"]).astype(np.float32)
        noisy["v_t"] = np.where(pad, rng.normal(size=pad.shape) * 1e3, batch["v_t"]).astype(np.float32)
        noisy["truncated_t"] = batch["truncated_t"] | (pad & (rng.random(pad.shape) < 0.5))
        adv2, ret2 = train.advantages_and_returns(**noisy, gamma=0.99, lambda_=1.0)
        np.testing.assert_array_equal(adv, adv2)
        np.testing.assert_array_equal(ret, ret2)
        np.testing.assert_array_equal(np.asarray(adv)[pad], 0.0)
        np.testing.assert_array_equal(np.asarray(ret)[pad], 0.0)

    def test_unbatched_time_axis_only(self):
        batch = make_batch(2)
        adv, ret = train.advantages_and_returns(**batch, gamma=0.9, lambda_=0.8)
        for b in range(4):
            lane = {k: (v[b] if k == "bootstrap_value" else v[:, b]) for k, v in batch.items()}
            adv_b, ret_b = train.advantages_and_returns(**lane, gamma=0.9, lambda_=0.8)
            chex.assert_shape(adv_b, (7,))
            np.testing.assert_allclose(adv_b, adv[:, b], rtol=1e-6)
            np.testing.assert_allclose(ret_b, ret[:, b], rtol=1e-6)

    def test_discounts(self):
        term = jnp.array([[0], [1], [0], [0]])
        trunc = jnp.zeros((4, 1))
        valid = jnp.array([[1], [1], [0], [0]])
        np.testing.assert_allclose(train.episode_discounts(term, trunc, valid, 0.9)[:, 0], [0.9, 0.0, 0.0, 0.0])
        # A valid step followed by padding without a done flag is not bootstrapped.
        valid = jnp.array([[1], [1], [1], [0]])
        np.testing.assert_allclose(
            train.episode_discounts(jnp.zeros((4, 1)), trunc, valid, 0.9)[:, 0],
            [0.9, 0.9, 0.0, 0.0],
        )

    def test_traced_once(self):
        fn = jax.jit(chex.assert_max_traces(lambda b: train.advantages_and_returns(**b, gamma=0.99, lambda_=1.0), n=1))
        for seed in range(3):
            jax.block_until_ready(fn(make_batch(seed)))


_TARGETS = jax.jit(train.advantages_and_returns, static_argnames=("gamma", "lambda_"))


@settings(max_examples=40, deadline=None)
@given(
    lengths=st.lists(st.integers(1, 8), min_size=3, max_size=3),
    ends=st.lists(st.sampled_from(["done", "time_limit", "running"]), min_size=3, max_size=3),
    seed=st.integers(0, 2**31 - 1),
    lam=st.sampled_from([1.0, 0.95, 0.0]),
)
def test_targets_property_vs_episode_loop(lengths, ends, seed, lam):
    """Random episode lengths and endings in a [T=8, B=3] rollout, vs the SAVN loop."""
    T, B = 8, 3
    rng = np.random.default_rng(seed)
    valid = np.arange(T)[:, None] < np.array(lengths)[None]
    terminated = np.zeros((T, B), bool)
    truncated = np.zeros((T, B), bool)
    for b, (length, end) in enumerate(zip(lengths, ends)):
        if end == "done":
            terminated[length - 1, b] = True
        elif end == "time_limit":
            truncated[length - 1, b] = True
    r = rng.normal(size=(T, B)).astype(np.float32)
    v = rng.normal(size=(T, B)).astype(np.float32)
    bootstrap = rng.normal(size=B).astype(np.float32)
    adv, ret = _TARGETS(r, v, terminated, truncated, valid, bootstrap, gamma=0.99, lambda_=lam)
    exp_adv, exp_ret = savn_style_targets(r, v, terminated, truncated, valid, bootstrap, 0.99, lam)
    np.testing.assert_allclose(adv, exp_adv, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(ret, exp_ret, rtol=1e-4, atol=1e-5)


class SmoothL1Test(chex.TestCase):
    @chex.variants(with_jit=True, without_jit=True)
    def test_hand_values(self):
        pred = jnp.array([0.5, 2.0, -1.0, 0.0])
        out = self.variant(imagination.smooth_l1)(pred, jnp.zeros(4))
        # 0.5 * 0.25, 2 - 0.5, |-1| - 0.5 (boundary), 0 -> mean over the 4 dims
        np.testing.assert_allclose(out, (0.125 + 1.5 + 0.5 + 0.0) / 4)

    def test_beta_and_batch(self):
        pred = jnp.array([[1.0, 3.0], [0.0, -4.0]])
        target = jnp.array([[0.0, 0.0], [0.0, 0.0]])
        out = imagination.smooth_l1(pred, target, beta=2.0)
        chex.assert_shape(out, (2,))
        # beta 2: 0.5 * 1 / 2 = 0.25, 3 - 1 = 2; 0, 4 - 1 = 3
        np.testing.assert_allclose(out, [(0.25 + 2.0) / 2, (0.0 + 3.0) / 2])

    def test_gradient_is_clipped(self):
        grad = jax.grad(lambda p: imagination.smooth_l1(p, jnp.zeros(2)))(jnp.array([0.4, -7.0]))
        np.testing.assert_allclose(grad, [0.4 / 2, -1.0 / 2])


def np_a3c_loss(logits, a, v, adv, ret, valid, ent_coef, val_coef):
    logits = np.asarray(logits, np.float64)
    logp = logits - logits.max(-1, keepdims=True)
    logp = logp - np.log(np.exp(logp).sum(-1, keepdims=True))
    logp_a = np.take_along_axis(logp, a[..., None], -1)[..., 0]
    ent = -(np.exp(logp) * logp).sum(-1)
    n = valid.sum()
    pg = (-(logp_a * adv) * valid).sum() / n
    entropy = (ent * valid).sum() / n
    value = (0.5 * (v - ret) ** 2 * valid).sum() / n
    return pg - ent_coef * entropy + val_coef * value, pg, entropy, value


class A3CLossTest(chex.TestCase):
    def setUp(self):
        super().setUp()
        rng = np.random.default_rng(3)
        T, B, A = 6, 3, 6
        self.logits = rng.normal(size=(T, B, A)).astype(np.float32)
        self.a = rng.integers(0, A, size=(T, B))
        self.v = rng.normal(size=(T, B)).astype(np.float32)
        self.adv = rng.normal(size=(T, B)).astype(np.float32)
        self.ret = rng.normal(size=(T, B)).astype(np.float32)
        self.valid = (np.arange(T)[:, None] < np.array([6, 2, 4])[None]).astype(np.float32)

    def args(self):
        return (self.logits, self.a, self.v, self.adv, self.ret, self.valid)

    @chex.variants(with_jit=True, without_jit=True)
    def test_matches_numpy(self):
        loss, metrics = self.variant(train.a3c_loss)(*self.args(), 0.01, 0.5)
        chex.assert_shape(loss, ())
        total, pg, entropy, value = np_a3c_loss(*self.args(), 0.01, 0.5)
        np.testing.assert_allclose(loss, total, rtol=1e-5)
        np.testing.assert_allclose(metrics["losses/policy_gradient_loss"], pg, rtol=1e-5)
        np.testing.assert_allclose(metrics["losses/entropy"], entropy, rtol=1e-5)
        np.testing.assert_allclose(metrics["losses/value_loss"], value, rtol=1e-5)
        np.testing.assert_allclose(metrics["losses/num_valid_steps"], 12.0)

    def test_gradients(self):
        def f(logits, v, adv, ret):
            return train.a3c_loss(logits, self.a, v, adv, ret, self.valid, 0.01, 0.5)[0]

        g_logits, g_v, g_adv, g_ret = jax.grad(f, argnums=(0, 1, 2, 3))(self.logits, self.v, self.adv, self.ret)
        # Targets are constants.
        np.testing.assert_array_equal(g_adv, 0.0)
        np.testing.assert_array_equal(g_ret, 0.0)
        # d/dv of 0.5 * mean(0.5 (v - R)^2) = 0.5 (v - R) valid / n.
        np.testing.assert_allclose(g_v, 0.5 * (self.v - self.ret) * self.valid / 12, rtol=1e-5)
        # Padding steps get no gradient.
        pad = self.valid == 0
        np.testing.assert_array_equal(np.asarray(g_logits)[pad], 0.0)
