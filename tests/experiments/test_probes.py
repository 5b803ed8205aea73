"""The probes of a trained agent's imagination (`experiments.analysis.probes`), against
independent references: the shuffled i_tau, f_w's fit against its baselines (the category
mean, ridge with its leave-one-out penalty, f_w trained offline), the replay of f_w's
online training (bit for bit the Trainer's), the signal-to-noise and sub-goal histogram,
how episodes end, and the training options replayed over a model
(`experiments.running.probe_runs.fit_options`)."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

import train_helpers as H
from experiments.analysis import probes
from experiments.running import models, probe_runs
from foresit_jax import imagination
from foresit_jax.networks import ImaginationNet, build


def first_observations(batch=4, seed=0):
    """A batch of first observations of the tiny bathroom environment."""
    env, env_params = H.bathroom_env()
    obs, _ = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(jax.random.PRNGKey(seed), batch), env_params)
    return obs


@pytest.mark.slow
def test_shuffled_imagination_imagines_from_another_episode():
    """The probe's networks (`probes.shuffled`) make each lane's i_tau where
    acting makes it (`imagination.imagine`, noise off) from the previous lane's s_0 and target;
    the unshuffled networks from the lane's own."""
    config = H.tiny_config("a3c+foresit")
    nets = build(config)
    shuffled = probes.shuffled(nets)
    rng = np.random.default_rng(0)
    s_0, goal = (jnp.asarray(rng.normal(size=(5, n)), jnp.float32) for n in (config.hidden_size, 300))
    _, w = nets.init(jax.random.PRNGKey(0), jax.tree.map(lambda x: x[0], first_observations()))

    def i_tau(n):  # with the noise off
        return np.asarray(imagination.imagine(n.imagination, w, s_0, goal, jax.random.PRNGKey(1), jnp.zeros(5), None))

    got, own = i_tau(shuffled), i_tau(nets)
    for b in range(5):
        np.testing.assert_allclose(got[b], nets.imagine(w, s_0[b - 1], goal[b - 1]), rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(own[b], nets.imagine(w, s_0[b], goal[b]), rtol=1e-5, atol=1e-6)


def test_imagination_fit_against_hand_computed_values():
    rng = np.random.default_rng(0)
    goals = np.repeat(np.eye(3), 20, axis=0)  # 3 categories, 60 items, alternating halves
    rng.shuffle(goals)
    centres = rng.normal(size=(3, 4)) * 2
    target = goals @ centres + 0.1 * rng.normal(size=(60, 4))
    perfect = probes.imagination_fit(target, target, goals)
    assert perfect["r2_over_mean"] == 1.0 and perfect["smooth_l1"] == 0.0 and perfect["r2_over_category"] == 1.0
    # Predicting each category's centre: about as good as the category baseline, much better than the mean.
    fit = probes.imagination_fit(goals @ centres, target, goals)
    assert fit["r2_over_mean"] > 0.95 and abs(fit["r2_over_category"]) < 0.2
    held = np.arange(1, 60, 2)
    mean = target[::2].mean(0)
    sse = ((target[held] - goals[held] @ centres) ** 2).sum()
    assert fit["r2_over_mean"] == pytest.approx(1 - sse / ((target[held] - mean) ** 2).sum())
    # The mean itself explains nothing.
    assert probes.imagination_fit(np.tile(mean, (60, 1)), target, goals)["r2_over_mean"] == pytest.approx(
        0.0, abs=1e-12
    )


def test_probe_baselines_recover_known_answers():
    """s_0 as the sub-goal is exact where the sub-goal is s_0; ridge on [s_0 : g] recovers
    a linear map (noise-free: R^2 1, the map's coefficients) and scores a noisy one as a
    hand computation with its chosen penalty does."""
    rng = np.random.default_rng(3)
    goals = np.repeat(np.eye(4), 30, axis=0)
    s_0 = rng.normal(size=(120, 6))
    same = probes.imagination_fit(np.zeros_like(s_0), s_0, goals, s_0=s_0)
    assert same["identity_r2_over_mean"] == 1.0 and same["ridge_r2_over_mean"] > 0.999
    w_true, b_true = rng.normal(size=(10, 6)), rng.normal(size=6)
    x = np.concatenate([s_0, goals], axis=1)
    linear = x @ w_true + b_true
    w, b, alpha = probes.ridge_fit(x[::2], linear[::2])
    assert alpha == min(probes.RIDGE_ALPHAS)
    np.testing.assert_allclose(x @ w + b, linear, atol=1e-3)  # the map (the one-hot columns are collinear with b)
    fit = probes.imagination_fit(np.zeros_like(linear), linear, goals, s_0=s_0)
    assert fit["ridge_r2_over_mean"] > 0.9999 and fit["identity_r2_over_mean"] < 0.5
    noisy = linear + rng.normal(size=linear.shape) * 3
    fit = probes.imagination_fit(np.zeros_like(noisy), noisy, goals, s_0=s_0)
    w, b, alpha = probes.ridge_fit(x[::2], noisy[::2])
    assert fit["ridge_alpha"] == alpha
    held = noisy[1::2]
    sse = ((held - (x[1::2] @ w + b)) ** 2).sum()
    assert fit["ridge_r2_over_mean"] == pytest.approx(1 - sse / ((held - noisy[::2].mean(0)) ** 2).sum())


def test_ridge_penalty_is_the_brute_force_leave_one_out_choice():
    """The closed-form leave-one-out errors choose the penalty a loop that refits without
    each item chooses (numpy's lstsq on the augmented system, an independent reference)."""
    rng = np.random.default_rng(4)
    x, y = rng.normal(size=(25, 8)), rng.normal(size=(25, 3))
    y += x[:, :2] @ rng.normal(size=(2, 3))  # some signal, much noise: a middle penalty wins

    def loo(alpha):
        sse = 0.0
        for i in range(len(x)):
            keep = np.arange(len(x)) != i
            xm, ym = x[keep].mean(0), y[keep].mean(0)
            a = np.vstack([x[keep] - xm, np.sqrt(alpha) * np.eye(x.shape[1])])
            t = np.vstack([y[keep] - ym, np.zeros((x.shape[1], y.shape[1]))])
            w = np.linalg.lstsq(a, t, rcond=None)[0]
            sse += float(((y[i] - ym - (x[i] - xm) @ w) ** 2).sum())
        return sse

    alphas = (1e-2, 1.0, 10.0, 30.0, 100.0, 1e4)
    errors = [loo(a) for a in alphas]
    _, _, chosen = probes.ridge_fit(x, y, alphas)
    assert chosen == alphas[int(np.argmin(errors))]
    assert alphas[int(np.argmin(errors))] not in (alphas[0], alphas[-1])  # the case tests a choice


def test_offline_f_w_fits_what_a_teacher_f_w_computes():
    """f_w's architecture trained offline on the even items of a teacher f_w's outputs
    predicts the odd ones far better than the untrained f_w (from which it starts)."""
    net = ImaginationNet((32, 16, 8, 16, 32, 16))  # f_w as Networks.imagine applies it, at H = 16
    rng = np.random.default_rng(5)
    n = 400
    goal = rng.normal(size=(n, 8)).astype(np.float32)
    s_0 = rng.normal(size=(n, 16)).astype(np.float32)
    teacher, w_init = (net.init(jax.random.PRNGKey(k), s_0[0], goal[0]) for k in (1, 2))
    target = 3 * np.asarray(net.apply(teacher, s_0, goal))
    w, steps = probes.fit_imagination_offline(net.apply, w_init, s_0, goal, target)
    assert steps > 0
    fit = probes.imagination_fit(
        np.asarray(net.apply(w_init, s_0, goal)), target, goal, s_0=s_0, offline=np.asarray(net.apply(w, s_0, goal))
    )
    assert fit["offline_r2_over_mean"] > 0.6 > fit["r2_over_mean"] + 0.5  # measured: 0.74 against -0.11


def test_only_fit_items_are_the_even_items_in_the_order_of_a_boolean_index():
    add = np.random.default_rng(6).random((5, 3, 4)) < 0.4
    x = np.arange(add.size).reshape(add.shape)
    np.testing.assert_array_equal(x[probes.only_fit_items(add)], x[add][::2])


GOAL_SIZE = 8  # the goal vectors of the replay streams below


def replay_stream(config, steps: int, seed: int, offered: float):
    """(trainer, a stream of random items (s_0, goal, subgoal, add) `[steps, lanes, ...]`,
    each step offering its item with probability `offered`, f_w's initial w)."""
    trainer, rng = H.trainer(config), np.random.default_rng(seed)
    lanes, hidden = config.num_lanes, config.hidden_size
    items = (
        rng.normal(size=(steps, lanes, hidden)).astype(np.float32),
        rng.normal(size=(steps, lanes, GOAL_SIZE)).astype(np.float32),
        rng.normal(size=(steps, lanes, hidden)).astype(np.float32),
        rng.random((steps, lanes)) < offered,
    )
    return trainer, items, trainer.networks.imagination_net.init(jax.random.PRNGKey(0), items[0][0, 0], items[1][0, 0])


def test_replayed_online_fit_is_the_training_procedure():
    """`replay_online_fit` streaming items twice gives the f_w `imagination.store_and_train`
    gives from the same start on the stream written twice (the procedure training runs,
    here two items a step), bit for bit."""
    config = H.tiny_config("a3c+foresit", buffer_size=4, imagination_epochs=2, imagination_batch=2)
    trainer, items, w0 = replay_stream(config, steps=6, seed=7, offered=0.5)
    buffers = jax.tree.map(
        lambda x: jnp.broadcast_to(x, (config.num_lanes,) + x.shape),
        imagination.buffer_init(config.buffer_size, config.hidden_size, GOAL_SIZE),
    )
    doubled = tuple(jnp.asarray(np.concatenate([x, x])) for x in items)
    want, _, _ = jax.jit(functools.partial(imagination.store_and_train, trainer.networks.imagination))(
        w0, buffers, doubled
    )
    got = probes.replay_online_fit(
        trainer.networks.imagine,
        w0,
        *items,
        trainer.imagination_optimizer,
        config.imagination_epochs,
        config.buffer_size,
        passes=2,
        batch=2,
    )
    H.assert_trees_bitwise_equal(got, want)
    assert not H.trees_bitwise_equal(got, w0)


def test_the_replay_can_keep_one_optimizer_state_across_flushes():
    """`replay_online_fit(..., keep_optimizer_state=True)` hands Adam's state from flush to
    flush (imagination.train_on_full_buffers, tested in test_imagination): another f_w
    than a fresh state per flush, from the same start on the same items."""
    config = H.tiny_config("a3c+foresit", buffer_size=2)
    trainer, items, w0 = replay_stream(config, steps=4, seed=9, offered=0.7)
    fresh, kept = (
        probes.replay_online_fit(
            trainer.networks.imagine, w0, *items, optax.adam(1e-2), 1, config.buffer_size, keep_optimizer_state=keep
        )
        for keep in (False, True)
    )
    assert not H.trees_bitwise_equal(fresh, w0)
    assert not H.trees_bitwise_equal(kept, fresh)


def test_signal_to_noise_and_subgoal_histogram_by_hand():
    s = probes.signal_to_noise(np.array([[1.0, 0.0], [-1.0, 2.0]]), 0.5)  # variances 1 and 1
    assert s == {"signal_variance": 1.0, "noise_variance": 0.5, "signal_share": pytest.approx(2 / 3)}
    h = probes.subgoal_position_histogram(np.array([0, 2, 4, 9, 0]), np.array([9, 9, 4, 9, 0]), bins=2)
    # ratios 0, 2/9, 1, 1, and T = 0 counts as 1 -> [0, 0.5): 2, [0.5, 1]: 3; t* = T in 3 of 5 (4/4, 9/9, 0/0)
    assert h["episodes"] == 5 and h["shares"] == [0.4, 0.6] and h["at_done"] == pytest.approx(0.6)
    with pytest.raises(ValueError, match="outside"):
        probes.subgoal_position_histogram(np.array([5]), np.array([4]))


def test_episode_endings_on_hand_made_episodes():
    """probes.episode_endings: a success at its third step, a Done that failed at its first
    (4 actions from success, outside the target's room) and a time-out, counted by hand."""
    T, DONE = 4, 5
    valid = np.array([[1, 1, 1, 0], [1, 0, 0, 0], [1, 1, 1, 1]], bool)
    success = np.zeros((3, T), bool)
    success[0, 2] = True
    actions = np.array([[0, 1, DONE, 0], [DONE, 0, 0, 0], [0, 0, 1, 2]])
    d = np.array([[3, 2, 1, 1], [4, 4, 4, 4], [9, 8, 7, 7]])
    in_room = np.array([[1, 1, 1, 1], [0, 0, 0, 0], [0, 0, 1, 1]], bool)
    p_done = np.array([[0.1, 0.2, 0.9, 0.5], [0.3, 0.5, 0.5, 0.5], [0.0, 0.1, 0.0, 0.2]])
    out = probes.episode_endings(valid, success, actions, p_done, d, in_room, DONE)
    assert out["all"] == {"episodes": 3, "success": 1 / 3, "failed Done": 1 / 3, "time-out": 1 / 3}
    assert out["failed Done"] == {
        "episodes": 1,
        "median actions": 1.0,
        "early share": 1.0,
        "median d at Done": 4.0,
        "in target room share": 0.0,
    }
    assert out["p_done"]["would succeed"] == pytest.approx(0.9)
    assert out["p_done"]["would fail"] == pytest.approx((0.1 + 0.2 + 0.3 + 0.0 + 0.1 + 0.0 + 0.2) / 7)
    assert out["start in target room"]["success"] == 1.0 and out["start away"]["episodes"] == 2
    with pytest.raises(ValueError, match="Done would succeed"):
        probes.episode_endings(valid, success, actions, p_done, np.ones_like(d), in_room, DONE)


@pytest.mark.slow
def test_fit_options_replay_each_option_on_the_fit_items_and_score_the_held_out_ones():
    """`experiments.running.probe_runs.fit_options` on items `[windows, T, B]`: one R^2 per option of
    FIT_OPTIONS; 'as trained' is the run's own procedure replayed on the even items and
    scored on the odd ones against their mean, as a direct computation gives it."""
    config = H.tiny_config("a3c+foresit", buffer_size=8)
    trainer = H.trainer(config)
    rng = np.random.default_rng(8)
    shape = (3, 5, config.num_lanes)
    items = (
        rng.normal(size=shape + (16,)).astype(np.float32),
        rng.normal(size=shape + (8,)).astype(np.float32),
        rng.normal(size=shape + (16,)).astype(np.float32),
        rng.random(shape) < 0.6,
    )
    w0 = trainer.networks.imagination_net.init(jax.random.PRNGKey(0), items[0][0, 0, 0], items[1][0, 0, 0])
    model = models.Model(config, trainer, 0, None, None)
    got = probe_runs.fit_options(model, w0, items, passes=2)
    assert list(got) == list(probe_runs.FIT_OPTIONS) and all(np.isfinite(v) for v in got.values())
    small = models.Model(dataclasses.replace(config, buffer_size=2), trainer, 0, None, None)
    assert np.isnan(probe_runs.fit_options(small, w0, items, passes=1)["batch 8"])  # 8 does not divide 2
    flat = [x.reshape((-1,) + x.shape[2:]) for x in items]
    add = flat[3]
    w = probes.replay_online_fit(
        trainer.networks.imagine,
        w0,
        *flat[:3],
        probes.only_fit_items(add),
        trainer.imagination_optimizer,
        config.imagination_epochs,
        config.buffer_size,
        2,
    )
    target = flat[2][add]
    predicted = np.asarray(trainer.networks.imagine(w, flat[0][add][1::2], flat[1][add][1::2]))
    assert got["as trained"] == pytest.approx(probes.r_squared(predicted, target[1::2], target[::2].mean(0)))
