"""foresit_jax.imagination: buffers, the f_w update, success rates and noise."""

import collections

import chex
import jax
import jax.numpy as jnp
import numpy as np
from absl.testing import parameterized

from foresit_jax import imagination, networks

H, D, M = 8, 3, 4  # small state, goal and buffer sizes for tests

NET = networks.ImaginationNet(layer_sizes=(16, 4, 16, 16, 16, H))


def apply_fn(params, s_0, goal):
    return NET.apply(params, s_0, goal)


def init_params(seed=0):
    return NET.init(jax.random.key(seed), jnp.zeros(H), jnp.zeros(D))


def random_item(rng):
    return (
        np.tanh(rng.normal(size=H)).astype(np.float32),
        rng.normal(size=D).astype(np.float32),
        np.tanh(rng.normal(size=H)).astype(np.float32),
    )


def filled_buffer(rng, n, capacity=M):
    buffer = imagination.buffer_init(capacity, H, D)
    for _ in range(n):
        buffer = imagination.buffer_add(buffer, *random_item(rng), True)
    return buffer


def stack(trees):
    return jax.tree.map(lambda *x: jnp.stack(x), *trees)


class BufferTest(chex.TestCase):
    @chex.variants(with_jit=True, without_jit=True)
    def test_adds_only_successes_in_order(self):
        rng = np.random.default_rng(0)
        add = self.variant(imagination.buffer_add)
        buffer = imagination.buffer_init(M, H, D)
        kept = []
        for success in [True, False, True, False, False, True]:
            item = random_item(rng)
            buffer = add(buffer, *item, jnp.array(success))
            if success:
                kept.append(item)
        self.assertEqual(int(buffer.count), 3)
        self.assertFalse(bool(imagination.buffer_is_full(buffer)))
        for i, (s0, g, sg) in enumerate(kept):
            np.testing.assert_array_equal(buffer.s_0[i], s0)
            np.testing.assert_array_equal(buffer.goal[i], g)
            np.testing.assert_array_equal(buffer.subgoal[i], sg)
        np.testing.assert_array_equal(buffer.s_0[3], 0.0)

    def test_full_at_capacity_and_drops_beyond(self):
        rng = np.random.default_rng(1)
        buffer = filled_buffer(rng, M)
        self.assertTrue(bool(imagination.buffer_is_full(buffer)))
        before = buffer
        buffer = imagination.buffer_add(buffer, *random_item(rng), True)
        chex.assert_trees_all_equal(buffer, before)
        cleared = imagination.buffer_clear(buffer)
        chex.assert_trees_all_equal(cleared, imagination.buffer_init(M, H, D))

    def test_per_lane_independence_under_vmap(self):
        rng = np.random.default_rng(2)
        B = 3
        buffers = jax.vmap(lambda _: imagination.buffer_init(M, H, D))(jnp.arange(B))
        add = jax.jit(jax.vmap(imagination.buffer_add))
        outcomes = np.array([[1, 0, 1], [1, 0, 0], [1, 1, 0]], bool)  # [updates, B]
        for success in outcomes:
            items = stack([random_item(rng) for _ in range(B)])
            buffers = add(buffers, *items, success)
        np.testing.assert_array_equal(buffers.count, outcomes.sum(0))
        chex.assert_shape(buffers.s_0, (B, M, H))


@jax.jit
def item_loss_and_grad(params, s_0, goal, subgoal):
    return jax.value_and_grad(lambda p: imagination.smooth_l1(apply_fn(p, s_0, goal), subgoal))(params)


def brute_force_train(params, buffer, optimizer, epochs):
    """Reference for train_on_buffer: Python loops, one optax step per item."""
    opt_state = optimizer.init(params)
    step_losses = np.zeros((epochs, buffer.capacity))
    apply_step = jax.jit(optimizer.update)
    for e in range(epochs):
        for i in range(buffer.capacity):
            loss, grads = item_loss_and_grad(params, buffer.s_0[i], buffer.goal[i], buffer.subgoal[i])
            step_losses[e, i] = loss
            updates, opt_state = apply_step(grads, opt_state, params)
            params = jax.tree.map(lambda p, u: p + u, params, updates)
    return params, step_losses


def brute_force_batched(params, buffer, optimizer, epochs, batch):
    """Reference for train_on_buffer with `batch` items a step: the mean of the items'
    losses and gradients (the loss is a mean over the batch), consecutive items in order."""
    opt_state = optimizer.init(params)
    step_losses = np.zeros((epochs, buffer.capacity // batch))
    for e in range(epochs):
        for j in range(buffer.capacity // batch):
            parts = [
                item_loss_and_grad(params, buffer.s_0[i], buffer.goal[i], buffer.subgoal[i])
                for i in range(j * batch, (j + 1) * batch)
            ]
            step_losses[e, j] = np.mean([float(loss) for loss, _ in parts])
            grads = jax.tree.map(lambda *g: sum(g) / batch, *[g for _, g in parts])
            updates, opt_state = optimizer.update(grads, opt_state, params)
            params = jax.tree.map(lambda p, u: p + u, params, updates)
    return params, step_losses


class TrainTest(chex.TestCase):
    @parameterized.parameters(("sgd", 0.5, 2), ("adam", 1e-2, 4))
    def test_train_on_buffer_in_batches_matches_loop(self, name, lr, batch):
        rng = np.random.default_rng(5)
        buffer = filled_buffer(rng, M)
        optimizer = imagination.make_imagination_optimizer(name, lr)
        params = init_params()
        trained, step_losses, _ = jax.jit(
            lambda p, b: imagination.train_on_buffer(p, b, apply_fn, optimizer, 2, batch)
        )(params, buffer)
        chex.assert_shape(step_losses, (2, M // batch))
        ref_params, ref_losses = brute_force_batched(params, buffer, optimizer, 2, batch)
        chex.assert_trees_all_close(trained, ref_params, rtol=1e-4, atol=1e-6)
        np.testing.assert_allclose(step_losses, ref_losses, rtol=1e-4, atol=1e-7)

    @parameterized.parameters(("sgd", 0.5), ("adam", 1e-2))
    def test_train_on_buffer_matches_loop(self, name, lr):
        rng = np.random.default_rng(3)
        buffer = filled_buffer(rng, M)
        optimizer = imagination.make_imagination_optimizer(name, lr)
        params = init_params()
        trained, step_losses, _ = jax.jit(lambda p, b: imagination.train_on_buffer(p, b, apply_fn, optimizer, 3))(
            params, buffer
        )
        chex.assert_shape(step_losses, (3, M))
        ref_params, ref_losses = brute_force_train(params, buffer, optimizer, 3)
        chex.assert_trees_all_close(trained, ref_params, rtol=1e-4, atol=1e-6)
        np.testing.assert_allclose(step_losses, ref_losses, rtol=1e-4, atol=1e-7)
        # Training reduces the loss on the buffer.
        loss_of = lambda p: imagination.imagination_loss(apply_fn, p, *buffer[:3])
        self.assertLess(float(loss_of(trained)), float(loss_of(params)))

    @chex.variants(with_jit=True, without_jit=True)
    def test_sequential_update_from_full_lanes_only(self):
        rng = np.random.default_rng(4)
        optimizer = imagination.make_imagination_optimizer("adam", 1e-2)
        counts = [M, 2, M, 0]
        buffers = stack([filled_buffer(rng, n) for n in counts])
        shared = init_params()
        fn = self.variant(lambda p, b: imagination.train_full_buffers(p, b, apply_fn, optimizer, 2))
        new_shared, new_buffers, metrics = fn(shared, buffers)
        # Reference: lanes 0 then 2, each starting from the previous result.
        ref = shared
        ref_losses = []
        for lane in (0, 2):
            lane_buffer = jax.tree.map(lambda x: x[lane], buffers)
            ref, lane_losses = brute_force_train(ref, lane_buffer, optimizer, 2)
            ref_losses.append(lane_losses)
        chex.assert_trees_all_close(new_shared, ref, rtol=1e-4, atol=1e-6)
        np.testing.assert_array_equal(new_buffers.count, [0, 2, 0, 0])
        np.testing.assert_array_equal(new_buffers.s_0[0], 0.0)
        np.testing.assert_array_equal(new_buffers.s_0[1], buffers.s_0[1])  # untouched
        self.assertEqual(int(metrics["imagination/num_trained_lanes"]), 2)
        np.testing.assert_allclose(metrics["imagination/loss"], np.mean([l.mean() for l in ref_losses]), rtol=1e-4)
        np.testing.assert_allclose(
            metrics["imagination/first_epoch_loss"], np.mean([l[0].mean() for l in ref_losses]), rtol=1e-4
        )

    def test_a_kept_optimizer_state_carries_from_lane_to_lane(self):
        """With `opt_state` given, lanes 0 then 2 train with one Adam state carried across
        their buffers (one buffer at a time, the state handed on, gives the same parameters
        and state); without, each starts afresh, and the two differ."""
        rng = np.random.default_rng(12)
        optimizer = imagination.make_imagination_optimizer("adam", 1e-2)
        buffers = stack([filled_buffer(rng, n) for n in (M, 2, M, 0)])
        shared = init_params()
        kept = jax.jit(lambda p, b, s: imagination.train_on_full_buffers(p, b, apply_fn, optimizer, 1, 1, s))
        new_shared, new_buffers, _, state = kept(shared, buffers, optimizer.init(shared))
        # Reference: train_on_buffer (tested against a Python loop above) on lanes 0 then 2,
        # the state of one handed to the next.
        one_buffer = jax.jit(lambda p, b, s: imagination.train_on_buffer(p, b, apply_fn, optimizer, 1, 1, s))
        ref, ref_state = shared, optimizer.init(shared)
        for lane in (0, 2):
            ref, _, ref_state = one_buffer(ref, jax.tree.map(lambda x: x[lane], buffers), ref_state)
        chex.assert_trees_all_close(new_shared, ref, rtol=1e-4, atol=1e-6)
        chex.assert_trees_all_close(state, ref_state, rtol=1e-4, atol=1e-6)
        np.testing.assert_array_equal(new_buffers.count, [0, 2, 0, 0])
        fresh, _, _, none = jax.jit(lambda p, b: imagination.train_on_full_buffers(p, b, apply_fn, optimizer, 1))(
            shared, buffers
        )
        assert none is None
        assert (
            max(float(jnp.abs(a - b).max()) for a, b in zip(jax.tree.leaves(fresh), jax.tree.leaves(new_shared))) > 1e-4
        )

    def test_vmapped_over_seeds(self):
        """Seeds with different numbers of full lanes, in one vmapped call."""
        rng = np.random.default_rng(9)
        optimizer = imagination.make_imagination_optimizer("sgd", 0.5)
        per_seed = [stack([filled_buffer(rng, n) for n in counts]) for counts in ([1, 2], [M, M])]
        buffers = stack(per_seed)  # [S=2, B=2, M, ...]
        shared = stack([init_params(0), init_params(1)])
        train = lambda p, b: imagination.train_full_buffers(p, b, apply_fn, optimizer, 1)
        out = jax.jit(jax.vmap(train))(shared, buffers)
        for seed in range(2):
            one = jax.jit(train)(*jax.tree.map(lambda x: x[seed], (shared, buffers)))
            chex.assert_trees_all_close(jax.tree.map(lambda x: x[seed], out), one, rtol=1e-5, atol=1e-6)
        # Seed 0 has no full lane: its parameters are returned untouched.
        chex.assert_trees_all_equal(jax.tree.map(lambda x: x[0], out[0]), init_params(0))
        np.testing.assert_array_equal(out[2]["imagination/num_trained_lanes"], [0, 2])

    def test_no_full_lane_is_a_no_op(self):
        rng = np.random.default_rng(5)
        optimizer = imagination.make_imagination_optimizer("sgd", 0.1)
        buffers = stack([filled_buffer(rng, n) for n in (1, M - 1)])
        shared = init_params()
        new_shared, new_buffers, metrics = jax.jit(
            lambda p, b: imagination.train_full_buffers(p, b, apply_fn, optimizer, 2)
        )(shared, buffers)
        chex.assert_trees_all_equal(new_shared, shared)
        chex.assert_trees_all_equal(new_buffers, buffers)
        self.assertEqual(int(metrics["imagination/num_trained_lanes"]), 0)
        self.assertEqual(float(metrics["imagination/loss"]), 0.0)

    def test_trains_exactly_when_capacity_reached(self):
        """Simulated updates: lane 0 succeeds every update, lane 1 every other one."""
        rng = np.random.default_rng(6)
        capacity = 3
        optimizer = imagination.make_imagination_optimizer("sgd", 0.1)
        buffers = jax.vmap(lambda _: imagination.buffer_init(capacity, H, D))(jnp.arange(2))
        shared = init_params()

        @jax.jit
        @chex.assert_max_traces(n=1)
        def update(shared, buffers, items, success):
            buffers = jax.vmap(imagination.buffer_add)(buffers, *items, success)
            return imagination.train_full_buffers(shared, buffers, apply_fn, optimizer, 1)

        trained_at = []
        for u in range(8):
            success = jnp.array([True, u % 2 == 0])
            items = stack([random_item(rng) for _ in range(2)])
            new_shared, buffers, metrics = update(shared, buffers, items, success)
            n = int(metrics["imagination/num_trained_lanes"])
            changed = not all(
                np.array_equal(a, b) for a, b in zip(jax.tree.leaves(new_shared), jax.tree.leaves(shared))
            )
            self.assertEqual(changed, n > 0)
            trained_at.append(n)
            shared = new_shared
        # Lane 0 fills at updates 2 and 5; lane 1 (successes at 0, 2, 4) fills at 4.
        self.assertEqual(trained_at, [0, 0, 1, 0, 1, 1, 0, 0])
        np.testing.assert_array_equal(buffers.count, [2, 1])

    def test_losses_add_up_over_calls_before_one_mean(self):
        """A window's f_w metrics are the mean over every lane trained in any of its steps
        (two lanes with mean losses 0.2 and 0.4 in one call, one with 0.6 in the next: 0.4),
        not the mean of the calls' means (0.45)."""
        first = imagination.ImaginationLosses(*map(jnp.float32, (2.0, 0.2 + 0.4, 1.0, 0.5)))
        second = imagination.ImaginationLosses(*map(jnp.float32, (1.0, 0.6, 0.7, 0.4)))
        m = first.plus(second).metrics()
        np.testing.assert_allclose(
            [
                m["imagination/num_trained_lanes"],
                m["imagination/loss"],
                m["imagination/first_epoch_loss"],
                m["imagination/last_epoch_loss"],
            ],
            [3.0, 0.4, 1.7 / 3, 0.3],
            rtol=1e-6,
        )
        none = imagination.ImaginationLosses.zeros().metrics()  # no lane trained: zeros, not NaN
        self.assertEqual([float(v) for v in none.values()], [0.0, 0.0, 0.0, 0.0])

    def test_unknown_optimizer(self):
        with self.assertRaisesRegex(ValueError, "sgd"):
            imagination.make_imagination_optimizer("rmsprop", 0.1)


class SuccessTrackerTest(chex.TestCase):
    @chex.variants(with_jit=True, without_jit=True)
    def test_ring_average_matches_deque(self):
        rng = np.random.default_rng(7)
        update = self.variant(imagination.tracker_update)
        rate = self.variant(imagination.success_rate)
        tracker = imagination.tracker_init(10)
        self.assertEqual(float(rate(tracker)), 0.0)
        window = collections.deque(maxlen=10)
        for outcome in rng.random(27) < 0.4:
            tracker = update(tracker, jnp.array(outcome))
            window.append(float(outcome))
            np.testing.assert_allclose(rate(tracker), np.mean(window), rtol=1e-6)
        self.assertEqual(int(tracker.count), 10)

    def test_window_100_and_unfinished_episodes(self):
        rng = np.random.default_rng(8)
        outcomes = rng.random(250) < 0.3
        finished = rng.random(250) < 0.8
        tracker = imagination.tracker_init()
        update = jax.jit(imagination.tracker_update)
        for o, f in zip(outcomes, finished):
            tracker = update(tracker, o, f)
        np.testing.assert_allclose(imagination.success_rate(tracker), outcomes[finished][-100:].mean(), rtol=1e-6)

    def test_per_lane_vmap(self):
        trackers = jax.vmap(lambda _: imagination.tracker_init(100))(jnp.arange(2))
        for _ in range(3):
            trackers = jax.vmap(imagination.tracker_update)(trackers, jnp.array([True, False]))
        trackers = jax.vmap(imagination.tracker_update)(trackers, jnp.array([False, False]))
        np.testing.assert_allclose(jax.vmap(imagination.success_rate)(trackers), [0.75, 0.0])


class NoiseTest(chex.TestCase):
    def test_variance_schedule_hand_values(self):
        rho = jnp.array([0.0, 0.3, 0.5, 0.9, 0.95, 1.0])
        np.testing.assert_allclose(imagination.noise_variance(rho, 0.9), [0.9, 0.6, 0.4, 0.0, 0.0, 0.0], atol=1e-7)

    @chex.variants(with_jit=True, without_jit=True)
    def test_empirical_variance(self):
        n = 20000
        mean = jnp.broadcast_to(jnp.array([[0.5], [-0.2], [0.1]]), (3, n))  # [B, H]
        variance = jnp.array([0.9, 0.4, 0.0])  # [B]
        out = self.variant(imagination.add_imagination_noise)(jax.random.key(0), mean, variance)
        chex.assert_shape(out, (3, n))
        np.testing.assert_allclose(np.var(out, axis=1), variance, atol=0.03)
        np.testing.assert_allclose(np.mean(out, axis=1), [0.5, -0.2, 0.1], atol=0.03)
        np.testing.assert_array_equal(out[2], mean[2])  # sigma^2 = 0: exactly f_w's output

    def test_input_noise_is_one_draw_over_the_input_split_back(self):
        """Algorithm 1's placement: [s_0 : g] + eta, eta ~ N(0, sigma^2 I) over H + D, each
        lane at its own variance; variance 0 leaves the input as it is."""
        key = jax.random.key(4)
        s_0, goal = jnp.ones((3, H)), jnp.zeros((3, D))
        variance = jnp.array([0.0, 0.25, 4.0])
        noisy_s, noisy_g = imagination.add_input_noise(key, s_0, goal, variance)
        eta = np.asarray(jax.random.normal(key, (3, H + D)))
        want = np.concatenate([s_0, goal], -1) + eta * np.sqrt(np.asarray(variance))[:, None]
        np.testing.assert_allclose(np.concatenate([noisy_s, noisy_g], -1), want, rtol=1e-6)
        np.testing.assert_array_equal(noisy_s[0], s_0[0])
        np.testing.assert_array_equal(noisy_g[0], goal[0])

    def test_random_imagination(self):
        out = imagination.random_imagination(jax.random.key(1), (4, 10000), 0.5)
        chex.assert_shape(out, (4, 10000))
        out = np.asarray(out, np.float64)
        self.assertTrue(np.all(np.abs(out) < 1.0))
        z = np.arctanh(out)
        np.testing.assert_allclose(z.var(), 0.5, atol=0.02)
        np.testing.assert_allclose(z.mean(), 0.0, atol=0.02)
