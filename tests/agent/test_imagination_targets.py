"""foresit_jax.imagination's targets, imagination as a training target: the labels against independent
references (numpy loops, a bearing computed from the pose and the scene's cells, the
oracle's own i_tau), the loss against numpy, where the gradients go, and that a target
leaves the agent that acts the base's (aux_weight 0 reproduces the base bit for bit; the
evaluation program hashes as the base's)."""

import dataclasses
import functools
from types import SimpleNamespace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from benchmarks import trace_update
from foresit_jax import imagination, rollout
from foresit_jax.config import Config
from foresit_jax.imagination import smooth_l1
from foresit_jax.train import Trainer, loss_and_grad_with_target
from train_helpers import assert_trees_bitwise_equal, bathroom_env, tiny_config


def window(rng, T=7, B=3, H=4):
    """A hand-made window: episodes of random lengths back to back in each lane, some
    successful, padding (valid 0) at the end of lane 2."""
    ended = rng.random((T, B)) < 0.35
    success = ended & (rng.random((T, B)) < 0.6)
    terminated = success | (ended & (rng.random((T, B)) < 0.5))
    truncated = ended & ~terminated
    valid = np.ones((T, B), bool)
    valid[5:, 2] = False
    states = rng.normal(size=(T, B, H)).astype(np.float32)
    return states, terminated, truncated, success, valid


def success_labels_loop(states, terminated, truncated, success, valid):
    """The reference: for each step, walk forward to its episode's end in the window."""
    T, B, H = states.shape
    y, mask = np.zeros((T, B, H), np.float32), np.zeros((T, B), bool)
    for b in range(B):
        for t in range(T):
            if not valid[t, b] or terminated[t, b] or truncated[t, b]:
                continue  # padding, or the end step itself
            for e in range(t + 1, T):
                if valid[e, b] and (terminated[e, b] or truncated[e, b]):
                    if success[e, b]:
                        y[t, b], mask[t, b] = states[e, b], True
                    break
    return y, mask


@pytest.mark.parametrize("seed", range(6))
def test_success_labels_are_the_state_where_the_episode_succeeded(seed):
    states, terminated, truncated, success, valid = window(np.random.default_rng(seed))
    got = imagination.success_labels(*map(jnp.asarray, (states, terminated, truncated, success, valid)))
    y, mask = success_labels_loop(states, terminated, truncated, success, valid)
    np.testing.assert_array_equal(np.asarray(got.mask), mask)
    np.testing.assert_array_equal(np.asarray(got.y)[mask], y[mask])


def test_success_labels_on_a_window_written_by_hand():
    # lane 0: an episode of 3 steps that succeeds at t=2, then one cut by the window (t=3, 4);
    # lane 1: one that fails (time limit) at t=1, then one that succeeds at t=4.
    states = jnp.arange(5 * 2, dtype=jnp.float32).reshape(5, 2, 1)
    term = jnp.array([[0, 0], [0, 0], [1, 0], [0, 0], [0, 1]], bool)
    trunc = jnp.array([[0, 0], [0, 1], [0, 0], [0, 0], [0, 0]], bool)
    succ = jnp.array([[0, 0], [0, 0], [1, 0], [0, 0], [0, 1]], bool)
    got = imagination.success_labels(states, term, trunc, succ, jnp.ones((5, 2), bool))
    np.testing.assert_array_equal(got.mask, [[1, 0], [1, 0], [0, 1], [0, 1], [0, 0]])
    np.testing.assert_array_equal(got.y[:2, 0, 0], [4.0, 4.0])  # s_2 of lane 0
    np.testing.assert_array_equal(got.y[2:4, 1, 0], [9.0, 9.0])  # s_4 of lane 1


@pytest.mark.parametrize("target", ["compass", "success"])
def test_the_loss_against_numpy(target):
    rng = np.random.default_rng(3)
    config = tiny_config("a3c", aux_target=target)
    K = imagination.target_width(config)
    T, B, H = 5, 3, config.hidden_size
    states = rng.normal(size=(T, B, H)).astype(np.float32)
    y = rng.normal(size=(T, B, K)).astype(np.float32)
    mask = rng.random((T, B)) < 0.6
    params = imagination.target_head(config).init(jax.random.PRNGKey(0), jnp.zeros(H))
    kernel, bias = (np.asarray(params["params"]["out"][k]) for k in ("kernel", "bias"))
    loss, metrics = imagination.target_window_loss(
        config, params, jnp.asarray(states), imagination.TargetLabels(y, mask)
    )
    x = states @ kernel + bias - y
    if target == "compass":
        per_step = np.sum(x**2, axis=-1)
    else:
        a = np.abs(x)
        per_step = np.mean(np.where(a < 1, 0.5 * a**2, a - 0.5), axis=-1)
    np.testing.assert_allclose(loss, per_step[mask].mean(), rtol=1e-5)
    assert float(metrics["charts/aux_labelled"]) == mask.sum()
    empty, _ = imagination.target_window_loss(
        config, params, jnp.asarray(states), imagination.TargetLabels(y, np.zeros((T, B), bool))
    )
    assert float(empty) == 0.0


def test_smooth_l1_is_the_latents_loss():
    config = tiny_config("a3c", aux_target="goal_view")
    p, y = jnp.array([[0.2, -3.0]]), jnp.array([[0.0, 0.0]])
    np.testing.assert_allclose(imagination.target_step_loss(config.aux_target, p, y), smooth_l1(p, y))


def compass_reference(pos, heading, cells, grid):
    """The bearing and distance of the nearest target cell, from the agent's forward and
    right unit vectors (not the cue's atan2 of an absolute bearing)."""
    best = None
    for r in range(grid):  # row-major, the first of equally near cells
        for c in range(grid):
            if cells[r, c]:
                d2 = (r - pos[0]) ** 2 + (c - pos[1]) ** 2
                if best is None or d2 < best[0]:
                    best = (d2, r - pos[0], c - pos[1])
    _, dr, dc = best
    angle = heading * np.pi / 4  # clockwise from north
    forward = (-np.cos(angle), np.sin(angle))  # (row, col) of a unit step ahead
    right = (np.sin(angle), np.cos(angle))
    ahead, aside = dr * forward[0] + dc * forward[1], dr * right[0] + dc * right[1]
    dist = np.hypot(dr, dc)
    if dist == 0:
        return np.array([1.0, 0.0, 0.0])
    return np.array([ahead / dist, aside / dist, dist / grid])


def test_compass_labels_against_an_independent_bearing_across_auto_resets():
    config = tiny_config("a3c", aux_target="compass")
    env, params = bathroom_env()
    labelled = imagination.label_env(config, env)

    def step(carry, key):
        state, obs = carry
        k_act, k_env = jax.random.split(key)
        action = jax.random.randint(k_act, (), 0, 6)  # Done among them: episodes end and auto-reset
        obs2, state2, _, term, trunc, _ = labelled.step(k_env, state, action, params)
        return (state2, obs2), (
            obs["cue"],
            state.env_state.agent_pos,
            state.env_state.heading,
            state.env_state.scene,
            state.env_state.target,
            term | trunc,
        )

    obs, state = labelled.reset(jax.random.PRNGKey(1), params)
    _, (cue, pos, heading, scene, target, done) = jax.jit(
        lambda s, o: jax.lax.scan(step, (s, o), jax.random.split(jax.random.PRNGKey(2), 60))
    )(state, obs)
    assert int(done.sum()) >= 3  # several episodes, so labels cross auto-resets
    fake_traj = rollout.Trajectory(
        *([None] * 6),
        valid=jnp.ones(60, bool),
        **dict.fromkeys(["success", "episode_step", "s_0", "optimal_length", "room_type"]),
    )
    got = np.asarray(imagination.target_labels(config, {"cue": cue}, None, fake_traj).y)
    obj = np.asarray(params.bank.obj_cat)
    for t in range(60):
        cells = obj[int(scene[t])] == int(target[t])
        want = compass_reference(np.asarray(pos[t]), int(heading[t]), cells, env.grid_size)
        np.testing.assert_allclose(got[t], want, atol=1e-5, err_msg=f"step {t}")


@pytest.mark.slow
def test_the_goal_view_target_is_the_oracles_i_tau():
    """An oracle arm without noise records i_tau at each step; the goal_view label of the same
    window, from the same parameters, equals it wherever the episode began in the window
    (i_tau is held from the episode's start, imagined under these parameters)."""
    oracle = tiny_config("a3c+oracle", sigma2_max=0.0, num_steps=24)
    env, params = bathroom_env()
    trainer = Trainer(oracle, env, params)
    state = trainer.init(jax.random.PRNGKey(0))
    env_b = trainer.bind(params)
    _, traj, _ = jax.jit(trainer.act)(
        rollout.AgentParams(state.params, state.imagination_params), env_b, state.actor, jax.random.PRNGKey(3)
    )
    config = tiny_config("a3c", aux_target="goal_view")

    def goal_latent(obs):
        return trainer.networks.goal_latent(state.params, None, obs)

    got = imagination.target_labels(config, traj.inputs.obs, traj.states, traj, goal_latent).y
    began = np.maximum.accumulate(np.asarray(traj.episode_step) == 0, axis=0)  # [T, B]: its start is in the window
    assert began.sum() > 20
    np.testing.assert_allclose(np.asarray(got)[began], np.asarray(traj.inputs.imagined)[began], atol=1e-5)


def test_no_gradient_reaches_a_label():
    states, terminated, truncated, success, valid = window(np.random.default_rng(0))

    def label_sum(s):
        return imagination.success_labels(s, *map(jnp.asarray, (terminated, truncated, success, valid))).y.sum()

    assert not np.any(np.asarray(jax.grad(label_sum)(jnp.asarray(states))))


@pytest.fixture(scope="module")
def a3c_trainers():
    env, params = bathroom_env()
    base = tiny_config("a3c")
    return {
        name: Trainer(dataclasses.replace(base, **fields), env, params)
        for name, fields in {
            "base": {},
            "zero": dict(aux_target="compass", aux_weight=0.0),
            "compass": dict(aux_target="compass", aux_weight=1.0),
            "success": dict(aux_target="success", aux_weight=1.0),
            "goal_view": dict(aux_target="goal_view", aux_weight=1.0),
        }.items()
    }


def run(trainer, updates):
    state = trainer.init(jax.random.PRNGKey(0))
    return jax.jit(lambda s: trainer.run(s, trainer.env_params, updates))(state)


@pytest.mark.slow
def test_aux_weight_zero_reproduces_the_base_bit_for_bit(a3c_trainers):
    base, base_metrics = run(a3c_trainers["base"], 20)
    zero, zero_metrics = run(a3c_trainers["zero"], 20)
    assert_trees_bitwise_equal(base.params, zero.params)
    assert_trees_bitwise_equal(base.actor.env_state, zero.actor.env_state.env_state)  # the same actions taken
    for name in ("charts/success_rate", "losses/total_loss", "losses/grad_norm"):
        np.testing.assert_array_equal(base_metrics[name], zero_metrics[name])
    # the head trains all the same (its own loss at full weight)
    moved = jax.tree.map(
        lambda a, b: float(jnp.max(jnp.abs(a - b))),
        zero.targets.params,
        a3c_trainers["zero"].init(jax.random.PRNGKey(0)).targets.params,
    )
    assert min(jax.tree.leaves(moved)) > 0


@pytest.mark.slow
@pytest.mark.parametrize("name", ["compass", "success", "goal_view"])
def test_the_heads_gradient_reaches_the_encoder(a3c_trainers, name):
    """With the same window, aux_weight 1 changes the encoder's gradient from aux_weight 0's
    and leaves the critic's value head's (no path from the target to it)."""
    weighted = a3c_trainers[name]
    zero = Trainer(dataclasses.replace(weighted.config, aux_weight=0.0), weighted.env, weighted.env_params)
    state = weighted.init(jax.random.PRNGKey(0))
    env = weighted.bind(weighted.env_params)
    args = (state.params, state.imagination_params, env, state.actor, jax.random.PRNGKey(5), state.targets.params)
    (_, w_win), g1, h1 = jax.jit(functools.partial(loss_and_grad_with_target, weighted))(*args)
    (_, z_win), g0, h0 = jax.jit(functools.partial(loss_and_grad_with_target, zero))(*args)
    assert float(w_win.metrics["charts/aux_labelled"]) > 0
    enc1, enc0 = g1["params"]["encoder"], g0["params"]["encoder"]
    diff = jax.tree.map(lambda a, b: float(jnp.max(jnp.abs(a - b))), enc1, enc0)
    assert max(jax.tree.leaves(diff)) > 0
    assert_trees_bitwise_equal(g1["params"]["value_critic"], g0["params"]["value_critic"])
    assert_trees_bitwise_equal(h1, h0)  # the head's own gradient does not depend on lambda
    assert float(w_win.metrics["losses/aux_grad_ratio"]) > 0 and float(z_win.metrics["losses/aux_grad_ratio"]) == 0


@pytest.mark.slow
def test_the_evaluation_program_of_a_target_arm_is_the_bases(a3c_trainers):
    hashes = {}
    for name in ("base", "compass", "goal_view"):
        trainer = a3c_trainers[name]
        hashes[name] = trace_update.program_hashes(trainer, trainer.init(jax.random.PRNGKey(0)))
    assert hashes["compass"]["evaluate"] == hashes["base"]["evaluate"] == hashes["goal_view"]["evaluate"]
    assert hashes["compass"]["train"] != hashes["base"]["train"]


@pytest.mark.parametrize(
    "fields,words",
    [
        (dict(method="a3c+maml", rollout="episodes", gradient="through_rollout", num_steps=30), "replay"),
        (dict(method="a3c", gradient="through_rollout"), "replay"),
        (dict(method="a3c+oracle"), "privileged input"),
        (dict(method="a3c+compass", sigma2_max=0.0), "privileged input"),
    ],
)
def test_a_target_is_refused_where_the_loss_is_not_the_replays(fields, words):
    with pytest.raises(ValueError, match=words) as e:
        Config(aux_target="compass", **fields)
    assert "\n" not in str(e.value)


def test_an_unknown_target_and_a_negative_weight_are_refused():
    with pytest.raises(ValueError, match="aux_target must be one of"):
        Config(method="a3c", aux_target="compas")
    with pytest.raises(ValueError, match="aux_weight must be >= 0"):
        Config(method="a3c", aux_target="compass", aux_weight=-1.0)


def test_a_checkpoint_saved_before_the_targets_field_restores(tmp_path):
    """A run saved by 0.3.0 (RunnerState without `targets`) resumes: the field, None in the
    template and absent on disk, is restored as None."""
    from typing import Any, NamedTuple

    from experiments.running import checkpoint

    class Old(NamedTuple):
        params: Any
        memory: Any = None

    class New(NamedTuple):
        params: Any
        memory: Any = None
        targets: Any = None

    manager = checkpoint.checkpoint_manager(tmp_path / "ckpt", 2)
    checkpoint.save(manager, 1, {"states": Old({"w": jnp.arange(3.0)}), "best": jnp.ones(2)})
    manager.wait_until_finished()
    like = {"states": New({"w": jnp.zeros(3)}), "best": jnp.zeros(2)}
    restored = checkpoint.restore(manager, 1, like)
    assert isinstance(restored["states"], New) and restored["states"].targets is None
    np.testing.assert_array_equal(restored["states"].params["w"], [0.0, 1.0, 2.0])
    head = (jnp.full(2, 7.0),)
    checkpoint.save(manager, 2, {"states": New({"w": jnp.arange(3.0)}, None, head), "best": jnp.ones(2)})
    manager.wait_until_finished()
    again = checkpoint.restore(
        manager, 2, {"states": New({"w": jnp.zeros(3)}, None, (jnp.zeros(2),)), "best": jnp.zeros(2)}
    )
    np.testing.assert_array_equal(again["states"].targets[0], [7.0, 7.0])


def test_a_targets_diagnostics_are_shown_where_an_arm_recorded_them():
    from experiments.reporting import report

    base = {"diagnostics": {n: [1.0, 1.0] for n in report.DIAGNOSTICS}}
    target = {"diagnostics": {**base["diagnostics"], **{n: [0.5, 0.25] for n in report.TARGET_DIAGNOSTICS}}}
    assert "labelled_fraction" not in report.diagnostics_markdown({"a3c": [base]})
    md = report.diagnostics_markdown({"a3c": [base], "a3c@aux_target=success": [target]})
    header = next(line for line in md.splitlines() if line.startswith("| Method"))
    assert header.rstrip(" |").endswith("aux_loss | aux_labelled_fraction | aux_grad_ratio")
    last = [line for line in md.splitlines() if line.startswith("| a3c@aux_target=success")][-1]
    assert last.rstrip(" |").endswith("0.25 | 0.25 | 0.25")
    assert report.values([target], "charts/aux_labelled_fraction")[0] == 0.25


def test_the_head_probes_measures_by_hand():
    from experiments.running import target_probe as P

    y = np.array([[1.0, 0.0, 0.1], [0.0, 1.0, 0.3], [-1.0, 0.0, 0.5], [0.0, -1.0, 0.7]])
    assert P.r2(y[:, 2:], y[:, 2:]) == 1.0
    assert P.r2(y[:, 2:], np.full((4, 1), 0.4)) == 0.0  # the mean predicts nothing
    assert P.angular_error(y[:, :2], 3 * y[:, :2]) == pytest.approx(0.0, abs=1e-9)  # any scale
    rotated = np.stack([-y[:, 1], y[:, 0]], axis=1)  # every bearing turned by 90 degrees
    assert P.angular_error(y[:, :2], rotated) == pytest.approx(90.0)
    exact = P.head_metrics("compass", y, y, None, None)
    assert exact["learned"] and exact["r2_distance"] == 1.0 and exact["labelled_steps"] == 4
    mean = P.head_metrics("compass", y, np.broadcast_to(y.mean(axis=0), y.shape), None, None)
    assert not mean["learned"] and mean["r2_distance"] == 0.0
    latents = P.head_metrics("success", y, y + 0.01, y[:2], np.ones((2, 3)))
    assert latents["learned"] and latents["state_spread"] == 0.0 and latents["label_spread"] > 0
    assert P.head_metrics("success", y[:0], y[:0], y[:0], y[:0]) == {"labelled_steps": 0, "learned": False}


@pytest.mark.slow
def test_target_probe_scores_each_arms_head_from_a_sweep(tmp_path, capsys):
    import json

    from experiments import sweep, target_probe

    arms = ("a3c@aux_target=compass,aux_weight=1.0", "a3c@aux_target=goal_view,aux_weight=1.0")
    sweep.main(sweep.Args(methods=arms, seeds=2, preset="tiny", out=tmp_path / "s", num_updates=2, progress=False))
    with pytest.raises(ValueError, match="has no arm"):
        target_probe.main(target_probe.Args(run=tmp_path / "s", methods=("a3c",)))
    target_probe.main(target_probe.Args(run=tmp_path / "s", episodes=8))
    saved = json.loads((tmp_path / "s" / "targets_probe.json").read_text())
    assert set(saved["arms"]) == set(arms)
    assert [s["seed"] for s in saved["arms"][arms[0]]] == [0, 1]
    assert {"angular_error", "r2_distance"} <= set(saved["arms"][arms[0]][0])
    assert {"r2", "label_spread", "state_spread"} <= set(saved["arms"][arms[1]][0])
    with pytest.raises(ValueError, match="--overwrite"):
        target_probe.main(target_probe.Args(run=tmp_path / "s", episodes=8))


def test_every_target_says_whether_its_labels_are_privileged():
    """`imagination.PRIVILEGED_LABELS` names the Config's targets, no more, no fewer (its
    keys also spell the refusal of an unknown target)."""
    from foresit_jax.config import AUX_TARGETS

    assert tuple(imagination.PRIVILEGED_LABELS) == AUX_TARGETS[1:]


def test_the_content_control_gives_each_lane_the_labels_of_the_lane_before_it():
    """`aux_permute` (the plan's content control): the labels and their mask, rolled by one
    lane, so lane b learns lane b - 1's; refused without a target or with one lane."""
    from foresit_jax.config import Config

    T, B = 4, 3
    rng = np.random.default_rng(0)
    states = jnp.asarray(rng.normal(size=(T, B, 5)), jnp.float32)
    terminated = np.zeros((T, B), bool)
    terminated[2, 0] = terminated[1, 2] = True
    fake = SimpleNamespace(
        valid=jnp.ones((T, B), bool),
        terminated=jnp.asarray(terminated),
        truncated=jnp.zeros((T, B), bool),
        success=jnp.asarray(terminated),
    )
    for target in ("compass", "success"):
        obs = {"cue": jnp.asarray(rng.normal(size=(T, B, 3)), jnp.float32)}
        own = imagination.target_labels(Config(method="a3c", aux_target=target), obs, states, fake)
        moved = imagination.target_labels(Config(method="a3c", aux_target=target, aux_permute=True), obs, states, fake)
        for b in range(B):
            np.testing.assert_array_equal(moved.y[:, b], own.y[:, b - 1])
            np.testing.assert_array_equal(moved.mask[:, b], own.mask[:, b - 1])
        assert np.asarray(own.mask).any()
    with pytest.raises(ValueError, match="aux_permute=True .* needs aux_target"):
        Config(method="a3c", aux_permute=True)
    with pytest.raises(ValueError, match="at least 2 lanes"):
        Config(method="a3c", aux_target="compass", aux_permute=True, num_lanes=1)
