"""The privileged cues (envs.wrappers.CueWrapper) and the imaginations that read them
(`optaction`, `compass`, `startcompass`; docs/plans/ceiling_channels.md): copying the
optimal-action cue succeeds in the shortest number of actions; the compass equals a
brute-force reference; the start compass is held for its episode, lane by lane; the agent
sees the step's own cue, in the head and in the encoder, from the first step on; and the
plumbing test: a policy trained on the optimal action beats the critic alone by 30 points."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import train_helpers as H

from envs import catalog as C
from envs.wrappers import CUES, CueWrapper
from foresit_jax import imagination, rollout
from foresit_jax.methods import parse_method
from foresit_jax.networks import build
from foresit_jax.rollout import ActOptions, AgentParams, BoundEnv

LANES, STEPS = 16, 40


def run_cue(kit, cue: str, actions=None, seed: int = 0):
    """LANES lanes of `CueWrapper(kit.env, cue)` for STEPS steps: random actions (or, with
    `actions == "cue"`, the argmax of the optimal-action cue). Returns numpy (the cue before
    each step [T, B, K], the inner state before each step, done [T, B], success [T, B],
    optimal length [T, B])."""
    wrapped = CueWrapper(kit.env, cue)
    rng = np.random.default_rng(seed)
    random_actions = jnp.asarray(rng.integers(0, C.NUM_ACTIONS, (STEPS, LANES)), jnp.int32)
    env_keys = jax.random.split(jax.random.PRNGKey(seed + 1), STEPS * LANES).reshape(STEPS, LANES, -1)

    @jax.jit
    def run(reset_keys):
        obs, state = jax.vmap(wrapped.reset, in_axes=(0, None))(reset_keys, kit.params)

        def step(carry, xs):
            obs, state = carry
            keys, action = xs
            if actions == "cue":
                action = jnp.argmax(obs["cue"], -1).astype(jnp.int32)
            out = jax.vmap(wrapped.step, in_axes=(0, 0, 0, None))(keys, state, action, kit.params)
            next_obs, next_state, _, term, trunc, info = out
            return (next_obs, next_state), (
                obs["cue"],
                state.env_state,
                term | trunc,
                info["success"],
                info["optimal_length"],
            )

        return jax.lax.scan(step, (obs, state), (env_keys, random_actions))[1]

    return jax.tree.map(np.asarray, run(jax.random.split(jax.random.PRNGKey(seed), LANES)))


def reference_compass(bank, state, lane_t) -> np.ndarray:
    """(cos b, sin b, d / G) by brute force: every cell of the target's category, the
    nearest by Euclidean distance (first in row-major order on ties), and the bearing from
    the heading's own direction vector by dot and cross products (clockwise positive)."""
    t, b = lane_t
    scene, target = int(state.scene[t, b]), int(state.target[t, b])
    row, col, heading = int(state.agent_pos[t, b, 0]), int(state.agent_pos[t, b, 1]), int(state.heading[t, b])
    grid = bank["obj_cat"].shape[1]
    best = None
    for r in range(grid):
        for c in range(grid):
            if bank["obj_cat"][scene, r, c] == target:
                d2 = (r - row) ** 2 + (c - col) ** 2
                if best is None or d2 < best[0]:
                    best = (d2, r - row, c - col)
    _, d_row, d_col = best
    east, north = d_col, -d_row  # the target's direction, east and north
    h_row, h_col = C.HEADING_DELTAS[heading]
    h_east, h_north = h_col, -h_row
    norm = np.hypot(east, north) * np.hypot(h_east, h_north)
    cos = (east * h_east + north * h_north) / norm if norm else 1.0
    sin = -(h_east * north - h_north * east) / norm if norm else 0.0  # clockwise from the heading
    return np.array([cos, sin, np.hypot(east, north) / grid], np.float32)


@pytest.mark.slow  # 9 s cold: a scan of the wrapped env (docs/testing.md)
def test_copying_the_optimal_action_cue_succeeds_in_the_shortest_number_of_actions(savn_kit):
    cues, _, done, success, optimal = run_cue(savn_kit, "optimal_action", actions="cue")
    assert cues.shape[-1] == CUES["optimal_action"] and np.all(cues.sum(-1) == 1)
    for lane in range(LANES):
        end = int(np.argmax(done[:, lane]))
        assert done[end, lane], "every lane's first episode ends inside the window"
        assert success[end, lane] and end + 1 == optimal[end, lane]


@pytest.mark.parametrize("kit_name", ["savn_kit", "priors_kit"])
def test_the_compass_is_a_brute_force_bearing_and_distance(request, kit_name):
    """At 64 start poses of the split, each turned to a random heading."""
    kit = request.getfixturevalue(kit_name)
    wrapped = CueWrapper(kit.env, "compass")
    n = 64
    _, state = jax.vmap(kit.env.reset, in_axes=(0, None))(jax.random.split(jax.random.PRNGKey(0), n), kit.params)
    state = state.replace(heading=jnp.asarray(np.random.default_rng(0).integers(0, C.NUM_HEADINGS, n), jnp.int32))
    cues = np.asarray(jax.jit(jax.vmap(wrapped.compass, in_axes=(0, None)))(state, kit.params))
    batched = jax.tree.map(lambda x: np.asarray(x)[None], state)  # [1, N]: reference_compass's (t, b)
    for b in range(n):
        np.testing.assert_allclose(cues[b], reference_compass(kit.bank, batched, (0, b)), atol=1e-5)
    assert np.ptp(cues[:, 1]) > 1.5  # bearings on both sides are seen: the test can fail on a sign


@pytest.mark.slow  # 9 s cold: a scan of the wrapped env (docs/testing.md)
def test_the_start_compass_is_the_per_step_compass_of_its_episodes_start_lane_by_lane(savn_kit):
    per_step, state, done, _, _ = run_cue(savn_kit, "compass")
    held, held_state, _, _, _ = run_cue(savn_kit, "compass_at_start")
    jax.tree.map(np.testing.assert_array_equal, state, held_state)  # the same episodes
    starts = 0
    for b in range(LANES):
        start = per_step[0, b]
        for t in range(STEPS):
            if t and done[t - 1, b]:  # a new episode began at this step
                start = per_step[t, b]
                starts += 1
            np.testing.assert_array_equal(held[t, b], start)
    assert starts >= LANES // 2 and not np.array_equal(held, per_step)  # episodes ended; the cues differ


def test_cue_names_spaces_and_the_configs_that_carry_them(savn_kit):
    with pytest.raises(ValueError, match="cue must be one of"):
        CueWrapper(savn_kit.env, "map")
    for cue, width in CUES.items():
        space = CueWrapper(savn_kit.env, cue).observation_space(savn_kit.params)
        assert space.spaces["cue"].shape == (width,) and "view" in space.spaces
    for name in ("a3c+optaction", "a3c+compass", "a3c+startcompass"):
        method = parse_method(name)
        assert method.privileged and method.imagination_variant.reads_cue and method.attention_critic
        assert not method.imagination_variant.trains_imagination
        with pytest.raises(ValueError, match="set sigma2_max=0"):
            H.tiny_config(name)
        assert H.tiny_config(name, sigma2_max=0.0).pieces == method
    assert not parse_method("a3c+oracle").imagination_variant.reads_cue


@pytest.mark.parametrize("imagination_input", ["head", "encoder"])
def test_the_agent_sees_the_steps_own_cue_from_the_first_step(imagination_input):
    """Without compiling: the i_tau of a step is the observation's cue, zero-padded to H,
    at an episode's first step too (the encoder's zero before s_0 is not applied)."""
    config = H.tiny_config("a3c+compass", sigma2_max=0.0, imagination_input=imagination_input)
    nets = build(config)
    cue = jax.random.normal(jax.random.PRNGKey(0), (3, CUES["compass"]))
    hidden = config.hidden_size
    obs = {"cue": cue}
    carry = imagination.ImaginationCarry(imagined=jnp.ones((3, hidden)), s_0=jnp.zeros((3, hidden)), tracker=None)
    steps = jnp.array([0, 1, 7])
    expected = np.concatenate([np.asarray(cue), np.zeros((3, hidden - cue.shape[1]))], 1)
    acting = AgentParams(None, None, jnp.zeros(3))
    imagined, _ = imagination.at_step(nets.imagination, acting, None, carry, jnp.zeros((3, hidden)), steps, obs, None)
    np.testing.assert_array_equal(imagined, expected)
    seen = imagination.encoder_input(nets.imagination, carry, steps, obs)
    if imagination_input == "encoder":
        np.testing.assert_array_equal(seen, expected)
    else:
        assert seen is None


@pytest.mark.slow
@pytest.mark.parametrize("imagination_input", ["head", "encoder"])
def test_acting_records_the_cue_of_every_step(savn_kit, imagination_input):
    """A window of acting with the optimal-action cue records, at every step, the padded
    cue of the observation the step acted on, where the policy reads it."""
    config = H.tiny_config("a3c+optaction", sigma2_max=0.0, imagination_input=imagination_input, num_lanes=3)
    nets = build(config)
    env = BoundEnv(savn_kit.env, savn_kit.params)
    actor = rollout.start(nets, jax.random.PRNGKey(2), env, config.num_lanes)
    assert "cue" in actor.obs  # start wrapped the env itself
    params, w_params = jax.jit(nets.init, compiler_options=H.FAST_COMPILE)(
        jax.random.PRNGKey(1), jax.tree.map(lambda x: x[0], actor.obs)
    )
    acting = AgentParams(params, w_params, jnp.zeros((config.num_lanes,)))
    act = jax.jit(
        lambda a, k: rollout.act_window(nets, acting, env, a, k, 20, ActOptions(record_inputs=True)),
        compiler_options=H.FAST_COMPILE,
    )
    inputs = act(actor, jax.random.PRNGKey(3))[1].inputs
    cue = np.asarray(inputs.obs["cue"])
    seen = inputs.imagined if imagination_input == "head" else inputs.encoder_imagined
    np.testing.assert_array_equal(np.asarray(seen)[..., : cue.shape[-1]], cue)
    assert not np.asarray(seen)[..., cue.shape[-1] :].any()
    assert len({tuple(np.argmax(c, -1)) for c in cue}) > 1  # the cue changes along the window


PLUMBING = dict(
    preset="tiny",
    seed=0,
    num_updates=300,
    chunk_updates=300,
    val_episodes_per_room=10,
    test_episodes_per_room=50,
    progress=False,
)


@pytest.mark.slow  # about 90 s: three tiny runs of 300 updates (docs/plans/ceiling_channels.md)
def test_plumbing_the_optimal_action_beats_the_critic_by_30_points_through_head_and_encoder(tmp_path):
    from experiments import train as train_cli

    def test_sr(arm: str) -> float:
        out = tmp_path / str(len(list(tmp_path.iterdir())))
        train_cli.main(train_cli.Args(method=arm, out=out, **PLUMBING))
        return json.loads((out / "results_test.json").read_text())["results"]["overall"]["SR"]

    critic = test_sr("a3c+critic@learning_rate=3e-3")
    for channel in ("head", "encoder"):
        sr = test_sr(f"a3c+optaction@learning_rate=3e-3,sigma2_max=0,imagination_input={channel}")
        assert sr >= critic + 30, f"the optimal action through {channel}: SR {sr} against the critic's {critic}"
