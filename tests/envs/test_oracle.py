"""The oracle (bank.distance, env.shortest_path_length, env.optimal_action) against an
independent breadth-first search, and an oracle policy that must score SR = SPL = 1."""

import jax
import numpy as np
import pytest

from envs import catalog as C
from env_helpers import UNREACHABLE, bank_pose_index, cached_oracle, cached_reference_oracle, make_states
from env_reference import bfs_forward, reference_transition


@pytest.mark.parametrize(
    "kit_name, scenes", [("savn_kit", [0, 7, 12, 19]), ("org_kit", [3, 16]), ("priors_kit", [2, 11])]
)
def test_bank_distance_equals_reference_bfs(request, kit_name, scenes):
    """Every free-cell pose of scenes of each room type, every target of the scene."""
    kit = request.getfixturevalue(kit_name)
    grid = kit.bank["cell_type"].shape[1]
    for scene in scenes:
        oracle, poses = cached_reference_oracle(kit, scene)
        assert len(oracle) >= 3
        idx = bank_pose_index(poses, grid)
        for slot, (dist, goal) in oracle.items():
            expected = np.array([dist.get(tuple(int(v) for v in p), UNREACHABLE) for p in poses])
            got = kit.bank["distance"][scene, slot, idx]
            bad = np.flatnonzero(got != expected)
            assert len(bad) == 0, (
                f"scene {kit.bank['numbers'][scene]} target {kit.bank['targets'][scene, slot]}: "
                f"{len(bad)} poses differ, e.g. pose {poses[bad[0]]}: bank {got[bad[0]]}, reference {expected[bad[0]]}"
            )
            assert len(goal) > 0 and expected.max() < UNREACHABLE  # free floor is connected
        # The reversed-graph BFS agrees with a plain forward BFS from a few poses.
        cell_type = kit.bank["cell_type"][scene]
        dist, goal = oracle[0]
        for p in poses[:: max(1, len(poses) // 5)]:
            p = tuple(int(v) for v in p)
            assert bfs_forward(cell_type, p, goal) == dist[p]


def test_shortest_path_length_and_optimal_action_follow_the_reference(savn_kit):
    """Random states in one scene per room type: shortest_path_length equals the reference
    BFS distance, and optimal_action is Done exactly at distance 1 and otherwise leads (by
    the reference dynamics) to a pose one action closer."""
    kit = savn_kit
    rng = np.random.default_rng(13)
    scenes = np.array([0, 7, 12, 19])[np.arange(128) % 4]
    pos = np.array([rng.choice(np.argwhere(kit.bank["cell_type"][sc] == C.CELL_FLOOR)) for sc in scenes])
    slot = (rng.random(128) * kit.bank["num_targets"][scenes]).astype(int)
    heading, horizon = rng.integers(0, 8, 128), rng.integers(0, 2, 128)
    # A quarter of them on goal poses, so that Done is exercised.
    for i in range(0, 128, 4):
        _, goal = cached_oracle(kit, int(scenes[i]))[int(slot[i])]
        r, c, heading[i], horizon[i] = sorted(goal)[rng.integers(len(goal))]
        pos[i] = (r, c)
    states = make_states(kit.bank, scenes, slot, pos, heading, horizon)
    spl = jax.jit(jax.vmap(kit.env.shortest_path_length, in_axes=(0, None)))(states, kit.params)
    action = jax.jit(jax.vmap(kit.env.optimal_action, in_axes=(0, None)))(states, kit.params)
    for i in range(128):
        dist, _ = cached_oracle(kit, int(scenes[i]))[int(slot[i])]
        pose = (int(pos[i, 0]), int(pos[i, 1]), int(heading[i]), int(horizon[i]))
        d, a = dist[pose], int(action[i])
        assert int(spl[i]) == d, (i, pose)
        if d == 1:
            assert a == C.DONE, (pose, C.ACTIONS[a])
        else:
            nxt = reference_transition(kit.bank["cell_type"][scenes[i]], pose, a)
            assert a != C.DONE and dist[nxt] == d - 1, (pose, C.ACTIONS[a], dist[nxt], d)


@pytest.mark.parametrize("kit_name", ["savn_kit", "org_kit", "priors_kit"])
def test_oracle_policy_scores_sr_1_and_spl_1(request, kit_name):
    """2048 vmapped episodes under evaluation limits: following optimal_action succeeds in
    every episode with exactly the optimal number of actions (SPL = 1)."""
    kit = request.getfixturevalue(kit_name)
    np.testing.assert_array_equal(kit.params.max_steps, [100, 200, 100, 100])
    keys = jax.random.split(jax.random.key(17), 2048)
    success, length, optimal, alive = kit.first_episodes(keys, np.ones(2048, bool))
    assert not alive.any()
    sr = success.mean()
    spl = np.mean(success * optimal / np.maximum(length, optimal))
    assert sr == 1.0 and spl == 1.0, (sr, spl)
    np.testing.assert_array_equal(length, optimal)
    assert (optimal >= 5).mean() > 0.3 and optimal.max() > 15
