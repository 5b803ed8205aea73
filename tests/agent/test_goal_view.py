"""The privileged goal view (envs.wrappers.GoalViewWrapper) and the `oracle` imagination
that reads it: the goal view is the view at the end of a shortest path found by an
independent breadth-first search, each episode holds its own (after auto-resets too, lane
by lane), and i_tau with the noise off is one network step on it."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import train_helpers as H

from env_helpers import cached_oracle, make_states
from env_reference import reference_transition
from envs.wrappers import GoalViewWrapper
from experiments.analysis.probes import shuffled
from foresit_jax import imagination, rollout
from foresit_jax.config import Config
from foresit_jax.lstm import initial_carry
from foresit_jax.methods import parse_method
from foresit_jax.networks import build
from foresit_jax.rollout import ActOptions, AgentParams, BoundEnv

N = 48  # reset keys per kit


def reference_goal_pose(kit, scene: int, slot: int, pose: tuple) -> tuple:
    """The end of a shortest path from `pose` by the reference BFS (tests/env_reference.py),
    ties broken as the environment's oracle breaks them (the first action, in action order,
    that brings the pose one action closer)."""
    dist = cached_oracle(kit, scene)[slot][0]
    cell_type = kit.bank["cell_type"][scene]
    while dist[pose] > 1:
        pose = next(
            q for q in (reference_transition(cell_type, pose, a) for a in range(5)) if dist[q] == dist[pose] - 1
        )
    return pose


@pytest.mark.parametrize("kit_name", ["savn_kit", "org_kit"])
def test_goal_view_is_the_view_at_the_end_of_a_reference_shortest_path(request, kit_name):
    kit = request.getfixturevalue(kit_name)
    wrapped = GoalViewWrapper(kit.env)
    keys = jax.random.split(jax.random.PRNGKey(3), N)
    obs, state = jax.jit(jax.vmap(wrapped.reset, in_axes=(0, None)))(keys, kit.params)
    obs, inner = jax.tree.map(np.asarray, obs), jax.tree.map(np.asarray, state.env_state)
    assert set(obs) == set(wrapped.observation_space(kit.params).spaces)
    ends, scenes, slots = [], inner.scene, inner.target_slot
    for i in range(N):
        start = (int(inner.agent_pos[i, 0]), int(inner.agent_pos[i, 1]), int(inner.heading[i]), int(inner.horizon[i]))
        ends.append(reference_goal_pose(kit, int(scenes[i]), int(slots[i]), start))
    ends = np.array(ends)
    at_end = make_states(kit.bank, scenes, slots, ends[:, :2], ends[:, 2], ends[:, 3])
    expected = jax.tree.map(np.asarray, jax.vmap(kit.env.get_obs, in_axes=(0, None))(at_end, kit.params))
    np.testing.assert_array_equal(obs["goal_view"], expected["view"])
    if "detections" in expected:
        np.testing.assert_array_equal(obs["goal_detections"], expected["detections"])
        assert (expected["detections"][..., 0] * expected["detections"][..., -1]).sum(-1).all()  # the target seen
    np.testing.assert_array_equal(
        obs["view"], jax.vmap(kit.env.get_obs, in_axes=(0, None))(state.env_state, kit.params)["view"]
    )
    # Most starts are not already at their goal: the walk is tested, not skipped.
    assert (np.abs(obs["goal_view"] - obs["view"]).sum((1, 2, 3)) > 0).mean() > 0.5


@pytest.mark.slow  # 11.4 s cold (docs/testing.md)
def test_each_episode_holds_its_own_goal_view_after_auto_resets_lane_by_lane(savn_kit):
    """Lanes acting at random for 40 steps (many episodes end): at every step each lane's
    goal view is the goal of the episode it is in (computed alone from that episode's
    start), it changes only where an episode ended, and a lane run alone gets the goal
    views it gets beside the others (nothing crosses lanes)."""
    kit, lanes, steps = savn_kit, 12, 40
    wrapped = GoalViewWrapper(kit.env)
    goal_alone = jax.jit(lambda s: wrapped.goal_observation(s, kit.params)["goal_view"])
    rng = np.random.default_rng(0)
    actions = jnp.asarray(rng.integers(0, 6, (steps, lanes)), jnp.int32)
    env_keys = jax.random.split(jax.random.PRNGKey(6), steps * lanes).reshape(steps, lanes, -1)

    @jax.jit
    def run(reset_keys, env_keys, actions):
        obs, state = jax.vmap(wrapped.reset, in_axes=(0, None))(reset_keys, kit.params)

        def step(state, xs):
            keys, action = xs
            obs, state, _, term, trunc, _ = jax.vmap(wrapped.step, in_axes=(0, 0, 0, None))(
                keys, state, action, kit.params
            )
            return state, (obs["goal_view"], state.env_state, term | trunc)

        _, (goals, inner, done) = jax.lax.scan(step, state, (env_keys, actions))
        return obs["goal_view"], goals, inner, done

    keys = jax.random.split(jax.random.PRNGKey(5), lanes)
    first, goals, inner, done = jax.tree.map(np.asarray, run(keys, env_keys, actions))
    assert done.sum() >= lanes  # episodes ended and the lanes reset
    checked = 0
    for lane in range(lanes):
        previous = first[lane]
        for t in range(steps):
            if done[t, lane]:  # a new episode: its own goal, from its start state
                start = jax.tree.map(lambda x: x[t, lane], inner)
                np.testing.assert_array_equal(goals[t, lane], goal_alone(start))
                checked += 1
            else:
                np.testing.assert_array_equal(goals[t, lane], previous)
            previous = goals[t, lane]
    assert checked >= lanes
    lane = 4
    alone = jax.tree.map(
        np.asarray, run(keys[lane : lane + 1], env_keys[:, lane : lane + 1], actions[:, lane : lane + 1])
    )
    np.testing.assert_array_equal(alone[1][:, 0], goals[:, lane])


def small_config(**kw) -> Config:
    base = dict(
        method="a3c+oracle",
        num_lanes=6,
        num_steps=8,
        num_updates=2,
        hidden_size=16,
        imagination_layer_sizes=(16,),
        attention_size=8,
    )
    return Config(**{**base, **kw})


@pytest.mark.slow  # 11.6 s cold (docs/testing.md)
@pytest.mark.parametrize("imagination_input", ["head", "encoder"])
def test_oracle_i_tau_with_the_noise_off_is_one_network_step_on_the_goal_view(savn_kit, imagination_input):
    config = small_config(imagination_input=imagination_input)
    nets = build(config)
    env = BoundEnv(kit_env := savn_kit.env, savn_kit.params)
    obs, _ = kit_env.reset(jax.random.PRNGKey(0), savn_kit.params)
    params, w_params = jax.jit(nets.init, compiler_options=H.FAST_COMPILE)(jax.random.PRNGKey(1), obs)
    actor = rollout.start(nets, jax.random.PRNGKey(2), env, config.num_lanes)
    assert set(actor.obs) >= {"goal_view", "view", "target"}  # start wrapped the env itself
    acting = AgentParams(params, w_params, jnp.zeros((config.num_lanes,)))
    act = jax.jit(
        lambda a, k: rollout.act_window(nets, acting, env, a, k, 20, ActOptions(record_inputs=True)),
        compiler_options=H.FAST_COMPILE,
    )  # compile-bound: its checks compare values made here
    _, traj = act(actor, jax.random.PRNGKey(3))[:2]
    inputs = traj.inputs
    i_tau = inputs.imagined if imagination_input == "head" else None
    if i_tau is None:  # in the encoder: the i_tau it sees after the first step
        i_tau = inputs.encoder_imagined
    obs = inputs.obs
    goal_obs = {"view": obs["goal_view"], "target": obs["target"]}
    hidden, actions = config.hidden_size, config.num_actions
    shape = obs["target"].shape[:-1]
    enc = jnp.zeros(shape + (hidden,)) if imagination_input == "encoder" else None
    _, expected = nets.model.apply(
        params,
        initial_carry(shape, hidden),
        goal_obs,
        jnp.zeros(shape + (actions,)),
        enc,
        method=lambda m, *a: m.encoder(*a),
    )  # the flax cell's route, not acting's
    step = np.asarray(traj.episode_step)
    used = step > 0 if imagination_input == "encoder" else np.ones_like(step, bool)
    np.testing.assert_allclose(np.asarray(i_tau)[used], np.asarray(expected)[used], atol=1e-6)
    assert (step == 0).sum() > config.num_lanes  # several episodes began inside the window
    # With the noise on, i_tau is that latent plus noise, fixed for the episode.
    noisy = AgentParams(params, w_params, jnp.full((config.num_lanes,), 0.25))
    traj = jax.jit(
        lambda a, k: rollout.act_window(nets, noisy, env, a, k, 20, ActOptions(record_inputs=True)),
        compiler_options=H.FAST_COMPILE,
    )(actor, jax.random.PRNGKey(3))[1]
    if imagination_input == "head":
        diff = np.asarray(traj.inputs.imagined) - np.asarray(expected)
        assert 0.3 < diff.std() < 0.7  # sigma = 0.5


@pytest.mark.slow  # 8.3 s cold (docs/testing.md)
def test_shuffled_probe_shuffles_the_oracles_i_tau_across_episodes(savn_kit):
    """The probe's shuffle (`probes.shuffled`) applies to the oracle's goal latent where
    i_tau is made (`imagination.imagine`, noise off): lane b gets lane b - 1's."""
    config = small_config()
    nets = build(config)
    env = BoundEnv(savn_kit.env, savn_kit.params)
    obs, _ = savn_kit.env.reset(jax.random.PRNGKey(0), savn_kit.params)
    params, w_params = jax.jit(nets.init, compiler_options=H.FAST_COMPILE)(jax.random.PRNGKey(1), obs)
    actor = rollout.start(nets, jax.random.PRNGKey(2), env, config.num_lanes)
    kernels = nets.lstm_kernels(params)
    own = nets.goal_latent(params, kernels, actor.obs)

    def i_tau(n):  # with the noise off
        return imagination.imagine(
            n.imagination,
            w_params,
            actor.agent.imagination.s_0,
            actor.obs["target"],
            jax.random.PRNGKey(3),
            jnp.zeros((config.num_lanes,)),
            lambda: own,
        )

    np.testing.assert_array_equal(i_tau(nets), own)
    np.testing.assert_array_equal(i_tau(shuffled(nets)), jnp.roll(own, 1, axis=0))


def test_the_oracle_is_a_privileged_diagnostic_with_clear_errors():
    for name in ("a3c+oracle", "a3c+org+oracle"):
        method = parse_method(name)
        assert method.privileged and method.attention_critic and not method.imagination_variant.trains_imagination
    assert not any(parse_method(n).privileged for n in ("a3c", "a3c+foresit", "a3c+rnd", "a3c+critic"))
    with pytest.raises(ValueError, match="goal view"):
        small_config(imagination_noise="input")
    assert dataclasses.replace(small_config(), setup="org", method="a3c+org+oracle").pieces.privileged


def test_reports_label_the_oracle_privileged():
    from experiments.reporting import report, tables

    assert tables.arm_label("a3c+oracle@learning_rate=3e-4") == "a3c+oracle@learning_rate=3e-4 (privileged)"
    assert tables.arm_label("a3c+foresit") == "a3c+foresit"
    row = {"SR": 50.0, "SPL": 20.0, "SR>=5": 40.0, "SPL>=5": 15.0}
    results = {m: [{"overall": row}, {"overall": row}] for m in ("a3c+critic", "a3c+oracle")}
    md = report.table_markdown(report.table(results), "t")
    assert "a3c+oracle (privileged)" in md and "privileged: i_tau is" in md
    assert "privileged" not in report.table_markdown(report.table({"a3c": results["a3c+critic"]}), "t")


@pytest.mark.slow
@pytest.mark.parametrize("method, setup", [("a3c+oracle", "savn"), ("a3c+org+oracle", "org")])
def test_train_and_probe_an_oracle_run(tmp_path, method, setup, cheap_experiments):
    """`experiments.train --method a3c+oracle --preset tiny` (and its org form) trains and
    writes its results, labelled privileged; `experiments.probe` shuffles the oracle's
    i_tau and skips what only a trained f_w gives."""
    import json

    from experiments import probe
    from experiments import train as train_cli
    from experiments import rundir

    out = tmp_path / "run"
    train_cli.main(train_cli.Args(method=method, preset="tiny", seed=0, out=out, progress=False, setup=setup))
    assert "(privileged)" in (out / "results_test.md").read_text()
    tested = json.loads((out / "results_test.json").read_text())["results"]["overall"]["SR"]
    episodes = rundir.read_run_info(out)["schedule"]["test_episodes_per_room"]
    (seed,) = probe.main(probe.Args(run=out, episodes_per_room=episodes, windows=10))[method]
    assert seed["sr"]["trained"] == pytest.approx(tested)
    conditions = {"trained", "noise off", "shuffled", "shuffled, noise off"} | (
        {"sampled actions"} if setup == "org" else set()
    )
    assert set(seed["sr"]) == conditions  # no "untrained f_w": the oracle's i_tau owes nothing to f_w
    assert "fit" not in seed["items"]
