"""foresit_jax.networks against numpy implementations of the paper's equations."""

import functools

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
from absl.testing import parameterized

from foresit_jax import networks
from foresit_jax.networks import ActorCritic
from foresit_jax import imagination

H = 16  # small LSTM in tests (512 in the paper)
W, CV, D, A = 4, 5, 7, 6


def np_dense(p, x):
    x = np.asarray(x, np.float64) @ np.asarray(p["kernel"], np.float64)
    return x + np.asarray(p["bias"], np.float64) if "bias" in p else x


def sigmoid(x):
    return 1.0 / (1.0 + np.exp(-x))


def np_encoder(p, carry, obs, prev_probs):
    """Reference encoder for ONE unbatched step: loops over the 3 x W grid cells."""
    relu = lambda x: np.maximum(x, 0.0)
    goal = relu(np_dense(p["target_embed"], obs["target"]))  # [64]
    act = relu(np_dense(p["action_embed"], prev_probs))  # [10]
    cells = []
    for band in range(3):
        for col in range(W):
            pixel = relu(np_dense(p["view_conv"], obs["view"][band, col]))  # [64]
            cell = np.concatenate([pixel, goal, act])  # [138]
            cells.append(relu(np_dense(p["pointwise_conv"], cell)))
    x = np.concatenate(cells)  # row-major flatten of [3, W, 64]
    lstm = p["lstm"]
    c, h = (np.asarray(a, np.float64) for a in carry)
    gate = lambda g: np_dense(lstm["i" + g], x) + np_dense(lstm["h" + g], h)
    i, f, g, o = sigmoid(gate("i")), sigmoid(gate("f")), np.tanh(gate("g")), sigmoid(gate("o"))
    c = f * c + i * g
    h = o * np.tanh(c)
    return (c, h), h


def random_obs(rng, batch=()):
    return {
        "view": rng.random((*batch, 3, W, CV)).astype(np.float32),
        "target": rng.normal(size=(*batch, D)).astype(np.float32),
    }


def random_probs(rng, batch=()):
    return np.asarray(jax.nn.softmax(rng.normal(size=(*batch, A))), np.float32)


def random_params(rng, module, *args, scale=0.3, **kwargs):
    """Parameters of `module` drawn N(0, scale^2) from `rng` (no compiled initialisers:
    the numeric checks only need some parameters; `init` itself is exercised in
    `ActorCriticTest.test_init_is_finite_and_small_policy`)."""
    shapes = jax.eval_shape(functools.partial(module.init, **kwargs), jax.random.key(0), *args)
    return jax.tree.map(lambda x: jnp.asarray(rng.normal(size=x.shape) * scale, jnp.float32), shapes)


class EncoderTest(chex.TestCase):
    @classmethod
    def setUpClass(cls):
        super().setUpClass()
        rng = np.random.default_rng(0)
        cls.encoder = networks.Encoder(hidden_size=H)
        cls.params = random_params(rng, cls.encoder, networks.initial_carry((), H), random_obs(rng), random_probs(rng))

    def setUp(self):
        super().setUp()
        self.rng = np.random.default_rng(0)

    def test_parameter_shapes(self):
        shapes = jax.tree.map(jnp.shape, self.params["params"])
        self.assertEqual(shapes["view_conv"]["kernel"], (CV, 64))
        self.assertEqual(shapes["target_embed"]["kernel"], (D, 64))
        self.assertEqual(shapes["action_embed"]["kernel"], (A, 10))
        self.assertEqual(shapes["pointwise_conv"]["kernel"], (64 + 64 + 10, 64))
        self.assertEqual(shapes["lstm"]["ii"]["kernel"], (3 * W * 64, H))

    @chex.variants(with_jit=True, without_jit=True)
    def test_matches_numpy_over_steps(self):
        step = self.variant(self.encoder.apply)
        carry = networks.initial_carry((), H)
        np_carry = tuple(np.zeros(H) for _ in range(2))
        p = jax.tree.map(np.asarray, self.params["params"])
        for _ in range(3):  # the carry is threaded through
            obs, probs = random_obs(self.rng), random_probs(self.rng)
            carry, s_t = step(self.params, carry, obs, probs)
            np_carry, np_s = np_encoder(p, np_carry, obs, probs)
            chex.assert_shape(s_t, (H,))
            np.testing.assert_allclose(s_t, np_s, rtol=2e-4, atol=2e-5)
            np.testing.assert_allclose(carry[0], np_carry[0], rtol=2e-4, atol=2e-5)

    def test_batched_equals_unbatched(self):
        obs, probs = random_obs(self.rng, (3,)), random_probs(self.rng, (3,))
        carry = jax.tree.map(lambda x: x + 0.1, networks.initial_carry((3,), H))
        apply = jax.jit(self.encoder.apply)
        batched_carry, s_b = apply(self.params, carry, obs, probs)
        chex.assert_shape(s_b, (3, H))
        for b in range(3):
            one = jax.tree.map(lambda x: x[b], (carry, obs, probs))
            _, s_1 = apply(self.params, *one)
            np.testing.assert_allclose(s_b[b], s_1, rtol=1e-5, atol=1e-6)

    def test_reset_carry(self):
        carry = (jnp.ones((3, H)), 2 * jnp.ones((3, H)))
        c, h = networks.reset_carry(jnp.array([True, False, True]), carry)
        np.testing.assert_array_equal(c[:, 0], [0, 1, 0])
        np.testing.assert_array_equal(h[:, 0], [0, 2, 0])

    def test_object_graph_hook(self):
        class CountGraph(nn.Module):  # stand-in for the ORG module
            @nn.compact
            def __call__(self, detections, target):
                return nn.Dense(5)(detections.reshape(*detections.shape[:-2], -1))

        encoder = networks.Encoder(hidden_size=H, object_graph=CountGraph())
        obs = random_obs(self.rng)
        obs["detections"] = self.rng.random((9, 7)).astype(np.float32)
        carry = networks.initial_carry((), H)
        params = random_params(self.rng, encoder, carry, obs, random_probs(self.rng))
        self.assertEqual(params["params"]["lstm"]["ii"]["kernel"].shape, (3 * W * 64 + 5, H))
        self.assertIn("object_graph", params["params"])
        del obs["detections"]
        with self.assertRaisesRegex(ValueError, "detections"):
            encoder.apply(params, carry, obs, random_probs(self.rng))
        # Without the hook, detections are ignored.
        obs["detections"] = np.zeros((9, 7), np.float32)
        _, s = self.encoder.apply(self.params, carry, obs, random_probs(self.rng))
        chex.assert_shape(s, (H,))


class PolicyHeadTest(chex.TestCase):
    @parameterized.parameters(True, False)
    def test_linear_over_state_and_imagination(self, use_imagination):
        rng = np.random.default_rng(1)
        head = networks.PolicyHead(A, use_imagination)
        s, i = rng.normal(size=(2, H)).astype(np.float32), rng.normal(size=(2, H)).astype(np.float32)
        imagined = i if use_imagination else None
        params = jax.eval_shape(head.init, jax.random.key(0), s, imagined)
        kernel = params["params"]["actor"]["kernel"]
        chex.assert_shape(kernel, ((2 * H if use_imagination else H), A))
        params = jax.tree.map(lambda x: jnp.asarray(rng.normal(size=x.shape), jnp.float32), params)
        logits = head.apply(params, s, imagined)
        x = np.concatenate([s, i], -1) if use_imagination else s
        np.testing.assert_allclose(logits, np_dense(params["params"]["actor"], x), rtol=1e-5, atol=1e-5)

    def test_missing_imagination_raises(self):
        head = networks.PolicyHead(A, True)
        with self.assertRaisesRegex(ValueError, "imagined"):
            head.init(jax.random.key(0), jnp.zeros(H))


def np_mlp_value(p, x):
    return np_dense(p["out"], np.maximum(np_dense(p["hidden"], x), 0.0))[..., 0]


def np_attention_critic(p, states, valid):
    """Eq. 3-4, one row t at a time: alpha over j = 0..t valid, sqrt(t+1) scaling."""
    T = states.shape[0]
    values, alphas = np.zeros(T), np.zeros((T, T))
    for t in range(T):
        q = np_dense(p["query"], states[t])
        js = [j for j in range(t + 1) if valid[j]]
        scores = np.array([q @ np_dense(p["key"], states[j]) for j in js]) / np.sqrt(t + 1)
        w = np.exp(scores - scores.max())
        w /= w.sum()
        alphas[t, js] = w
        s_star = sum(wj * np_dense(p["value"], states[j]) for wj, j in zip(w, js)) + states[t]
        values[t] = np_mlp_value(p["value_head"], s_star)
    return values, alphas


class CriticTest(chex.TestCase):
    @classmethod
    def setUpClass(cls):
        super().setUpClass()
        rng = np.random.default_rng(2)
        cls.T = 6
        cls.states = np.tanh(rng.normal(size=(cls.T, H)) * 2).astype(np.float32)
        cls.valid = np.array([1, 1, 1, 1, 0, 0], bool)  # episode of 4 steps, 2 padding
        cls.critic = networks.Critic(attention=True, attention_size=8, value_hidden=12)
        shapes = jax.eval_shape(cls.critic.init, jax.random.key(3), cls.states, cls.valid)
        # Standard-normal weights make the attention far from uniform.
        cls.params = jax.tree.map(lambda x: jnp.asarray(rng.normal(size=x.shape), jnp.float32), shapes)

    @chex.variants(with_jit=True, without_jit=True)
    def test_matches_numpy_equations(self):
        out = self.variant(self.critic.apply)(self.params, self.states, self.valid)
        chex.assert_shape(out.value, (self.T,))
        chex.assert_shape(out.alpha, (self.T, self.T))
        chex.assert_shape(out.attended_state, (self.T, H))
        p = jax.tree.map(np.asarray, self.params["params"])
        values, alphas = np_attention_critic(p, self.states, self.valid)
        np.testing.assert_allclose(out.alpha, alphas, rtol=1e-4, atol=1e-6)
        np.testing.assert_allclose(out.value, values, rtol=1e-4, atol=1e-4)
        # Alpha is causal, sums to one, and never looks at padding.
        alpha = np.asarray(out.alpha)
        np.testing.assert_array_equal(np.triu(alpha, 1), 0.0)
        np.testing.assert_array_equal(alpha[:, ~self.valid], 0.0)
        np.testing.assert_allclose(alpha.sum(-1), 1.0, rtol=1e-5)
        self.assertGreater(alpha[3].max(), 0.5)  # non-trivial weights in this setup

    def test_padding_states_do_not_matter(self):
        apply = jax.jit(self.critic.apply)
        out = apply(self.params, self.states, self.valid)
        states = self.states.copy()
        states[~self.valid] = 1e3
        out2 = apply(self.params, states, self.valid)
        np.testing.assert_allclose(out.value[:4], out2.value[:4], rtol=1e-6)
        np.testing.assert_array_equal(out.alpha[:4], out2.alpha[:4])

    def test_per_row_sqrt_scaling(self):
        # Take key and query as the identity: scores_tj = s_t . s_j / sqrt(t+1).
        p = jax.tree.map(np.asarray, self.params["params"])
        p = dict(p)
        eye = dict(kernel=np.eye(H, dtype=np.float32), bias=np.zeros(H, np.float32))
        critic = networks.Critic(attention=True, attention_size=H, value_hidden=12)
        params = {"params": {**p, "query": eye, "key": eye}}
        valid = np.ones(self.T, bool)
        alpha = np.asarray(critic.apply(params, self.states, valid).alpha)
        for t in range(self.T):
            scores = self.states[: t + 1] @ self.states[t] / np.sqrt(t + 1)
            expected = np.exp(scores - scores.max())
            np.testing.assert_allclose(alpha[t, : t + 1], expected / expected.sum(), rtol=1e-5)

    def test_batched_over_lanes(self):
        states = np.stack([self.states, self.states[::-1]])  # [2, T, H]
        valid = np.stack([self.valid, np.ones(self.T, bool)])
        apply = jax.jit(self.critic.apply)
        out = apply(self.params, states, valid)
        chex.assert_shape(out.value, (2, self.T))
        for b in range(2):
            one = apply(self.params, states[b], valid[b])
            np.testing.assert_allclose(out.value[b], one.value, rtol=1e-5)
            np.testing.assert_allclose(out.alpha[b], one.alpha, rtol=1e-5)

    def test_plain_critic_is_mlp_on_state(self):
        critic = networks.Critic(attention=False, value_hidden=12)
        params = random_params(np.random.default_rng(1), critic, self.states, self.valid)
        self.assertEqual(set(params["params"]), {"value_head"})
        out = critic.apply(params, self.states, self.valid)
        self.assertIsNone(out.alpha)
        expected = np_mlp_value(jax.tree.map(np.asarray, params["params"]["value_head"]), self.states)
        np.testing.assert_allclose(out.value, expected, rtol=1e-5, atol=1e-6)

    def test_linear_value_head_is_one_dense_layer(self):
        """Config.value_head='linear' (SAVN's critic): V = s W + b, nothing else."""
        for attention in (False, True):
            critic = networks.Critic(attention=attention, attention_size=8, value_hidden=0)
            params = random_params(np.random.default_rng(2), critic, self.states, self.valid)
            head = jax.tree.map(np.asarray, params["params"]["value_head"])
            self.assertEqual(set(head), {"out"})
            out = critic.apply(params, self.states, self.valid)
            attended = np.asarray(out.attended_state)
            np.testing.assert_allclose(out.value, np_dense(head["out"], attended)[..., 0], rtol=1e-5, atol=1e-6)

    def test_default_sizes(self):
        critic = networks.Critic()
        states = jnp.zeros((5, 512))
        params = jax.eval_shape(critic.init, jax.random.key(0), states, jnp.ones(5, bool))
        shapes = jax.tree.map(lambda x: x.shape, params["params"])
        self.assertEqual(shapes["query"]["kernel"], (512, 512))
        self.assertEqual(shapes["key"]["kernel"], (512, 512))
        self.assertEqual(shapes["value"]["kernel"], (512, 512))
        self.assertEqual(shapes["value_head"]["out"]["kernel"], (256, 1))


def unroll_steps(model, params, carry, obs_t, prev_action_probs_t, imagined_t=None):
    """`ActorCritic.__call__` (one step through flax's own cell) scanned over a time-major
    sequence (one episode per lane, no reset): (final carry, states [T, ..., H], logits
    [T, ..., A])."""

    def body(carry, inputs):
        carry, s_t, logits, _ = model.apply(params, carry, *inputs)
        return carry, (s_t, logits)

    carry, (states, logits) = jax.lax.scan(body, carry, (obs_t, prev_action_probs_t, imagined_t))
    return carry, states, logits


class SubgoalTest(chex.TestCase):
    """subgoals_of_rows: the sub-goal each attention row selects (what the buffers get)."""

    def setUp(self):
        super().setUp()
        # Hand-made episode of 4 states plus one padding step.
        self.states = jnp.array([[3.0, 0, 0], [0, 3.0, 0], [0, 0, 1.0], [0, 2.0, 0], [9.0, 9.0, 9.0]])
        self.valid = jnp.array([1, 1, 1, 1, 0], bool)

    def test_identity_attention_picks_most_correlated_state(self):
        # q = k = identity: alpha of the last step T=3 ∝ exp(s_3 . s_j / 2),
        # dot products (0, 6, 0, 4) -> t* = 1.
        critic = networks.Critic(attention=True, attention_size=3, value_hidden=4)
        params = random_params(np.random.default_rng(0), critic, self.states, self.valid)
        eye = dict(kernel=jnp.eye(3), bias=jnp.zeros(3))
        params = {"params": {**params["params"], "query": eye, "key": eye}}
        alpha = critic.apply(params, self.states, self.valid).alpha
        alpha_last = alpha[3]
        expected = np.exp(np.array([0.0, 6.0, 0.0, 4.0]) / 2.0)
        np.testing.assert_allclose(alpha_last[:4], expected / expected.sum(), rtol=1e-5)
        self.assertEqual(float(alpha_last[4]), 0.0)
        subgoal = imagination.subgoals_of_rows(self.states, alpha[3:4])
        np.testing.assert_array_equal(subgoal, [[0.0, 3.0, 0.0]])

    @chex.variants(with_jit=True, without_jit=True)
    def test_select_modes(self):
        alpha = jnp.array([[0.1, 0.2, 0.4, 0.3, 0.0]])
        argmax = self.variant(lambda s, a: imagination.subgoals_of_rows(s, a, "argmax"))
        average = self.variant(lambda s, a: imagination.subgoals_of_rows(s, a, "attention_average"))
        np.testing.assert_array_equal(argmax(self.states, alpha), [[0.0, 0.0, 1.0]])
        np.testing.assert_allclose(
            average(self.states, alpha), [[0.1 * 3.0, 0.2 * 3.0 + 0.3 * 2.0, 0.4 * 1.0]], rtol=1e-6
        )
        # Ties go to the first index.
        tie = jnp.array([[0.0, 0.4, 0.2, 0.4, 0.0]])
        np.testing.assert_array_equal(argmax(self.states, tie), [[0.0, 3.0, 0.0]])

    def test_rows_batched_and_stop_gradient(self):
        states = jnp.stack([self.states, 2 * self.states])  # [2, K, 3]
        alpha = jnp.array([[[0, 0, 1.0, 0, 0], [1.0, 0, 0, 0, 0]], [[1.0, 0, 0, 0, 0], [0, 0, 0, 1.0, 0]]])
        out = imagination.subgoals_of_rows(states, alpha)  # [2, R=2, 3]
        chex.assert_shape(out, (2, 2, 3))
        np.testing.assert_array_equal(out, [[[0, 0, 1.0], [3.0, 0, 0]], [[6.0, 0, 0], [0, 4.0, 0]]])
        for mode in ("argmax", "attention_average"):
            grad = jax.grad(lambda s: imagination.subgoals_of_rows(s, alpha, mode).sum())(states)
            np.testing.assert_array_equal(grad, 0.0)
        with self.assertRaisesRegex(ValueError, "mode"):
            imagination.subgoals_of_rows(states, alpha, "median")


class ImaginationNetTest(chex.TestCase):
    def test_architecture_and_numpy_forward(self):
        net = networks.ImaginationNet()
        rng = np.random.default_rng(4)
        s0 = np.tanh(rng.normal(size=(3, 512))).astype(np.float32)
        goal = rng.normal(size=(3, 300)).astype(np.float32)
        params = random_params(rng, net, s0, goal, scale=0.05)
        layers = params["params"]
        self.assertEqual(len(layers), 6)
        sizes = [layers[f"layer_{i}"]["kernel"].shape for i in range(6)]
        self.assertEqual(sizes, [(812, 512), (512, 256), (256, 64), (64, 256), (256, 512), (512, 512)])
        self.assertEqual(min(s[1] for s in sizes), 64)  # bottleneck
        out = net.apply(params, s0, goal)
        chex.assert_shape(out, (3, 512))
        x = np.concatenate([s0, goal], -1)
        for i in range(6):
            x = np.tanh(np_dense(jax.tree.map(np.asarray, layers[f"layer_{i}"]), x))
        np.testing.assert_allclose(out, x, rtol=1e-4, atol=1e-5)

    def test_output_range(self):
        net = networks.ImaginationNet(layer_sizes=(32, 8, 32, 32, 32, 16))
        rng = np.random.default_rng(5)
        s0 = rng.normal(size=(64, 16)).astype(np.float32) * 10
        goal = rng.normal(size=(64, 22)).astype(np.float32) * 10
        params = random_params(rng, net, s0, goal, scale=1.0)
        out = np.asarray(jax.jit(net.apply)(params, s0, goal))
        chex.assert_shape(out, (64, 16))
        self.assertTrue(np.all(np.abs(out) <= 1.0))
        self.assertGreater(out.std(), 0.05)  # not collapsed


class ActorCriticTest(chex.TestCase):
    @classmethod
    def setUpClass(cls):
        super().setUpClass()
        rng = np.random.default_rng(6)
        cls.model = networks.ActorCritic(
            hidden_size=H, use_imagination=True, attention_critic=True, attention_size=8, value_hidden=12
        )
        cls.params = random_params(
            rng,
            cls.model,
            networks.initial_carry((), H),
            random_obs(rng),
            random_probs(rng),
            jnp.zeros(H),
        )

    def setUp(self):
        super().setUp()
        self.rng = np.random.default_rng(6)

    def test_parameter_tree(self):
        self.assertEqual(set(self.params["params"]), {"encoder", "policy", "value_critic"})
        self.assertEqual(self.params["params"]["policy"]["actor"]["kernel"].shape, (2 * H, A))

    def test_unroll_matches_step_loop_and_traces_once(self):
        T, B = 5, 2
        obs = random_obs(self.rng, (T, B))
        probs = random_probs(self.rng, (T, B))
        imagined = np.tanh(self.rng.normal(size=(T, B, H))).astype(np.float32)
        carry0 = networks.initial_carry((B,), H)
        unroll = jax.jit(chex.assert_max_traces(lambda p, c, o, pr, i: unroll_steps(self.model, p, c, o, pr, i), n=1))
        carry, states, logits = unroll(self.params, carry0, obs, probs, imagined)
        unroll(self.params, carry0, obs, probs, imagined + 0.1)  # no retrace
        chex.assert_shape(states, (T, B, H))
        chex.assert_shape(logits, (T, B, A))
        c = carry0
        step = jax.jit(self.model.apply)
        for t in range(T):
            c, s_t, l_t, _ = step(self.params, c, jax.tree.map(lambda x: x[t], obs), probs[t], imagined[t])
            np.testing.assert_allclose(states[t], s_t, rtol=1e-5, atol=1e-6)
            np.testing.assert_allclose(logits[t], l_t, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(carry[1], c[1], rtol=1e-5, atol=1e-6)
        # Critic over the unrolled states, lanes batched.
        out = self.model.apply(
            self.params,
            jnp.swapaxes(states, 0, 1),
            jnp.ones((B, T), bool),
            method=networks.ActorCritic.critic,
        )
        chex.assert_shape(out.value, (B, T))

    def test_init_is_finite_and_small_policy(self):
        params = jax.jit(self.model.init)(
            jax.random.key(0),
            networks.initial_carry((), H),
            random_obs(self.rng),
            random_probs(self.rng),
            jnp.zeros(H),
        )
        chex.assert_trees_all_equal_shapes(params, self.params)
        chex.assert_tree_all_finite(params)
        # SAVN-style small actor init: a near-uniform initial policy.
        kernel = np.asarray(params["params"]["policy"]["actor"]["kernel"])
        self.assertLess(np.abs(kernel).max(), 0.05)

    def test_encode_then_heads_equal_the_flax_cells_steps(self):
        """The one route (`encode` over a window, time-major, the carry zeroed where an
        episode begins, then `policy_logits`) against flax's own cell step by step (`__call__`),
        over two episodes in each lane; and `encode` at T = 1, step by step, as acting
        calls it, gives the same states."""
        steps, lanes = 6, 2
        obs, probs = random_obs(self.rng, (steps, lanes)), random_probs(self.rng, (steps, lanes))
        imagined = np.tanh(self.rng.normal(size=(steps, lanes, H))).astype(np.float32)
        first = np.zeros((steps, lanes), bool)
        first[[0, 3], 0] = first[[0, 4], 1] = True
        carry = jax.tree.map(lambda x: x + 0.3, networks.initial_carry((lanes,), H))  # zeroed at step 0
        apply = jax.jit(self.model.apply, static_argnames="method")
        inputs = networks.EncoderInputs(obs, probs)
        carry_a, states = apply(self.params, carry, inputs, jnp.asarray(first), method=ActorCritic.encode)
        logits = apply(self.params, states, imagined, method=ActorCritic.policy_logits)
        c, c_one = carry, carry
        for t in range(steps):
            c = jax.tree.map(lambda x: jnp.where(first[t][:, None], 0.0, x), c)
            c, s_t, l_t, _ = apply(self.params, c, jax.tree.map(lambda x: x[t], obs), probs[t], imagined[t])
            np.testing.assert_allclose(states[t], s_t, rtol=1e-5, atol=1e-6)
            np.testing.assert_allclose(logits[t], l_t, rtol=1e-5, atol=1e-6)
            one = jax.tree.map(lambda x: x[t : t + 1], inputs)
            c_one, s_one = apply(self.params, c_one, one, jnp.asarray(first[t : t + 1]), method=ActorCritic.encode)
            np.testing.assert_allclose(s_one[0], states[t], rtol=1e-5, atol=1e-6)
        chex.assert_trees_all_close(carry_a, c, rtol=1e-5, atol=1e-6)
        chex.assert_trees_all_close(c_one, c, rtol=1e-5, atol=1e-6)

    def test_baseline_without_imagination(self):
        model = networks.ActorCritic(hidden_size=H, use_imagination=False, attention_critic=False)
        carry = networks.initial_carry((), H)
        params = random_params(self.rng, model, carry, random_obs(self.rng), random_probs(self.rng))
        self.assertEqual(params["params"]["policy"]["actor"]["kernel"].shape, (H, A))
        self.assertEqual(set(params["params"]["value_critic"]), {"value_head"})
        carry_out, states, logits = jax.jit(functools.partial(unroll_steps, model))(
            params, carry, random_obs(self.rng, (3,)), random_probs(self.rng, (3,))
        )
        chex.assert_shape(logits, (3, A))
