"""Houses (``layout="house"``, envs.houses): generation, doorways and walls, the oracle
against the reference BFS, calibration, the start share, and a render of a house."""

from collections import deque

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from envs import bank as B
from envs import catalog as C
from envs import houses as H
from envs import render
from envs.gridnav import HOUSE_EVAL_TIME_LIMIT, HOUSE_TRAIN_TIME_LIMIT
from envs.metrics import LONG_PATH_MINS, summarize
from env_helpers import UNREACHABLE, Kit, bank_pose_index, cast_views, make_states, reference_oracle

ALL_HOUSES = [n for split in C.SPLITS for n in C.house_numbers(split)]


@pytest.fixture(scope="module")
def house_kit():
    """Kit of the savn test houses (15), evaluation limits, episodes as long as the limit."""
    env, params = envs.make("GridNav-v0", setup="savn", split="test", layout="house")
    return Kit(env, params, episode_steps=HOUSE_EVAL_TIME_LIMIT)


@pytest.fixture(scope="module")
def layouts():
    return {(n, setup): H.generate_house(n, setup) for n in ALL_HOUSES for setup in ("savn", "org")}


def components(free):
    """Connected components (4-neighbour) of a bool grid: int [G, G] labels, -1 off ``free``."""
    label = np.full(free.shape, -1)
    count = 0
    for start in map(tuple, np.argwhere(free)):
        if label[start] >= 0:
            continue
        label[start] = count
        queue = deque([start])
        while queue:
            r, c = queue.popleft()
            for nr, nc in ((r + 1, c), (r - 1, c), (r, c + 1), (r, c - 1)):
                if free[nr, nc] and label[nr, nc] < 0:
                    label[nr, nc] = count
                    queue.append((nr, nc))
        count += 1
    return label, count


def test_numbers_sizes_and_splits():
    assert C.house_numbers("train")[:2] == [2001, 2002] and len(C.house_numbers("train")) == 60
    assert C.house_numbers("val") == [1000 * s + n for s in (2, 3, 4) for n in (21, 23, 25, 27, 29)]
    assert C.house_numbers("test") == [1000 * s + n for s in (2, 3, 4) for n in (22, 24, 26, 28, 30)]
    assert [C.house_size_of(n) for n in (2001, 3030, 4015)] == [2, 3, 4]
    for bad in (1001, 2031, 5001, 230):
        with pytest.raises(ValueError, match="house number"):
            C.house_size_of(bad)
    with pytest.raises(ValueError, match="unknown layout 'houses'"):
        envs.make(layout="houses")
    for n in ALL_HOUSES:
        types = H.house_room_types(n)
        assert len(types) == C.house_size_of(n) and len(set(types)) == len(types)


def test_generation_is_deterministic_and_setups_share_the_walls(layouts):
    again = H.generate_house(3022, "org")
    first = layouts[(3022, "org")]
    for name in ("cell_type", "obj_cat", "obj_band", "cell_room"):
        np.testing.assert_array_equal(getattr(again, name), getattr(first, name))
    savn = layouts[(3022, "savn")]
    np.testing.assert_array_equal(savn.cell_room, first.cell_room)  # the rooms and doorways are the setup's
    assert not np.array_equal(savn.obj_cat, first.obj_cat)


def test_rooms_are_walled_apart_and_joined_by_doorways(layouts):
    """With the doorway cells (floor in no room) walled up, a house falls apart into exactly
    its rooms; with them open, its floor is one piece; each doorway is DOOR_WIDTH cells in
    a line, between two rooms."""
    for (number, setup), house in layouts.items():
        walkable = house.cell_type == C.CELL_FLOOR
        n = len(house.room_types)
        doors = walkable & (house.cell_room < 0)
        assert doors.sum() == (n - 1) * H.DOOR_WIDTH, number
        _, count = components(walkable)
        assert count == 1, number
        label, count = components(walkable & ~doors)
        assert count == n, (number, count)
        for room in range(n):  # a component is one room's floor, all of it
            assert len(np.unique(label[walkable & (house.cell_room == room)])) == 1, (number, room)
        door_label, _ = components(doors)
        for d in range(n - 1):
            cells = np.argwhere(door_label == d)
            assert len(cells) == H.DOOR_WIDTH and (np.ptp(cells[:, 0]) == 0 or np.ptp(cells[:, 1]) == 0)
            steps = ((1, 0), (-1, 0), (0, 1), (0, -1))
            beside = {int(house.cell_room[r + dr, c + dc]) for r, c in cells for dr, dc in steps}
            assert len(beside - {-1}) == 2, (number, beside)


def test_each_target_stands_once_in_a_room_of_its_type(layouts):
    for (number, setup), house in layouts.items():
        names = C.categories(setup)
        padded = np.pad(house.cell_room, 1, constant_values=-1)  # an object may hang on the outer wall
        wanted = {names.index(x) for t in house.room_types for x in C.SETUPS[setup][1][t]}
        present, counts = np.unique(house.obj_cat[house.obj_cat >= 0], return_counts=True)
        assert set(present.tolist()) == wanted == set(house.target_room) and (counts == 1).all(), number
        for cat, room in house.target_room.items():
            assert names[cat] in C.SETUPS[setup][1][house.room_types[room]]
            (r, c), band = np.argwhere(house.obj_cat == cat)[0], int(house.obj_band[house.obj_cat == cat][0])
            near = {int(padded[r + 1 + dr, c + 1 + dc]) for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1))}
            if band == C.BAND_HIGH:  # on a wall that faces its room's floor only
                assert house.cell_type[r, c] == C.CELL_WALL and near - {-1} == {room}, (number, names[cat], near)
            else:
                assert house.cell_room[r, c] == room, (number, names[cat])


def door_view_depth(house, door_open: bool):
    """The level mid-row depth straight ahead of an agent 2 cells in front of a doorway's
    middle cell, facing it (4 view columns: the middle two rays)."""
    walkable = house.cell_type == C.CELL_FLOOR
    label, _ = components(walkable & (house.cell_room < 0))
    doors = np.argwhere(label == 0)  # the first doorway's cells, in a line
    r, c = doors[1]  # its middle cell
    for heading, (dr, dc) in ((0, (1, 0)), (4, (-1, 0)), (2, (0, -1)), (6, (0, 1))):  # stand behind, face it
        pos = (r + 2 * dr, c + 2 * dc)
        if house.cell_room[pos] >= 0 and house.cell_type[r + dr, c + dc] == C.CELL_FLOOR and walkable[pos]:
            cell = house.cell_type.copy()
            if not door_open:
                cell[tuple(doors.T)] = C.CELL_WALL
            _, depth = cast_views(
                cell[None],
                house.obj_cat[None],
                house.obj_band[None],
                np.array([pos]),
                np.array([heading]),
                np.array([0]),
                view_width=4,
            )
            return depth[0, 1, 1:3]
    return None


def test_the_view_passes_doorways_and_stops_at_walls(layouts):
    """Facing a doorway from 2 cells: the rays go on into the next room; with the doorway
    walled up they stop where the wall begins, 1.5 cells away."""
    checked = 0
    for number in (2022, 3024, 4026, 4028, 3030):
        house = layouts[(number, "savn")]
        opened, closed = door_view_depth(house, True), door_view_depth(house, False)
        if opened is None:
            continue
        checked += 1
        np.testing.assert_allclose(closed, 1.5)
        assert (opened >= 2.5).all(), (number, opened)
    assert checked >= 3


def test_precomputed_views_equal_the_ray_cast_ones_up_to_the_camera_range(house_kit):
    """The bank's table equals a fresh ray cast at random poses, looking through doorways
    or not (the longest rays of the houses stop short of the camera's range, 31.9 cells:
    the bank's largest depth code is 252 of 255)."""
    kit = house_kit
    rng = np.random.default_rng(3)
    scene = rng.integers(0, len(kit.bank["numbers"]), 256)
    free = [np.argwhere(kit.bank["cell_type"][s] == C.CELL_FLOOR) for s in scene]
    pos = np.array([f[rng.integers(len(f))] for f in free])
    heading, horizon = rng.integers(0, 8, 256), rng.integers(0, 2, 256)
    grid = kit.bank["cell_type"].shape[1]
    pose = ((pos[:, 0] * grid + pos[:, 1]) * 8 + heading) * 2 + horizon
    sem, depth = cast_views(
        kit.bank["cell_type"][scene],
        kit.bank["obj_cat"][scene],
        kit.bank["obj_band"][scene],
        pos,
        heading,
        horizon,
        view_width=kit.env.view_width,
    )
    np.testing.assert_array_equal(kit.bank["view_sem"][scene, pose], sem)
    np.testing.assert_array_equal(kit.bank["view_depth"][scene, pose], depth * 8)
    assert depth.max() > 20


def test_depth_is_clipped_at_the_camera_range():
    """In an empty 44 x 44 room, looking north from 41.5 cells below the far wall, near the
    west wall: the rays that meet the far wall see MAX_DEPTH (the table's largest code),
    the one that meets the west wall within range sees its distance."""
    from envs.raycast import MAX_DEPTH

    cell = np.full((44, 44), C.CELL_WALL, np.int8)
    cell[1:-1, 1:-1] = C.CELL_FLOOR
    none = np.full(cell.shape, -1, np.int8)
    _, depth = cast_views(
        cell[None], none[None], none[None], np.array([[42, 3]]), np.array([0]), np.array([0]), view_width=4
    )
    assert MAX_DEPTH == 255 / 8 and depth[0, 1].max() == MAX_DEPTH and depth[0, 1].min() < MAX_DEPTH


@pytest.mark.parametrize("scene", [0, 7, 14])  # a 2-, a 3- and a 4-room house
def test_bank_distance_equals_reference_bfs(house_kit, scene):
    """Every free-cell pose, every target of the house: the bank's oracle is the reference
    BFS (goal poses from a fresh ray cast), and every target is reachable from everywhere."""
    kit = house_kit
    assert C.house_size_of(int(kit.bank["numbers"][scene])) == 2 + scene // 5
    oracle, poses = reference_oracle(kit, scene)
    idx = bank_pose_index(poses, kit.bank["cell_type"].shape[1])
    assert len(oracle) == kit.bank["num_targets"][scene] >= 8
    for slot, (dist, _) in oracle.items():
        expected = np.array([dist.get(tuple(int(v) for v in p), UNREACHABLE) for p in poses])
        np.testing.assert_array_equal(kit.bank["distance"][scene, slot, idx], expected)
        assert expected.max() < UNREACHABLE


def test_progress_reward_adds_the_reference_distance_gained(house_kit):
    """EnvParams.progress_reward w: each step's reward is the step penalty (the success
    reward on a successful Done) plus w (d_t - d_{t+1}), d the reference BFS's actions to
    success of the pose before and after the step (its dynamics the reference's too); with
    w = 0, the paper's reward, the step penalty alone."""
    from env_helpers import index_tree, make_states
    from env_reference import reference_transition

    kit, scene, slot, w = house_kit, 0, 1, 0.25
    oracle, _ = reference_oracle(kit, scene)
    dist, goal = oracle[slot]
    cell_type = kit.bank["cell_type"][scene]
    rng = np.random.default_rng(3)
    free = np.argwhere(cell_type == C.CELL_FLOOR)
    pose = (*(int(v) for v in free[rng.integers(len(free))]), 0, 0)
    state = index_tree(make_states(kit.bank, [scene], [slot], [pose[:2]], [0], [0]), 0)
    step = jax.jit(kit.env.step_env)
    shaped, plain = kit.params.replace(progress_reward=w), kit.params
    key = jax.random.key(0)
    gains = []
    for action in [*rng.integers(0, 5, 80), C.DONE]:
        _, new, reward, terminated, _, info = step(key, state, jnp.int32(action), shaped)
        after = pose if action == C.DONE else reference_transition(cell_type, pose, int(action))
        gains.append(dist[pose] - dist[after])
        base = 5.0 if action == C.DONE and pose in goal else -0.01
        assert float(reward) == pytest.approx(base + w * gains[-1], abs=1e-5), (pose, action)
        assert float(step(key, state, jnp.int32(action), plain)[2]) == pytest.approx(base, abs=1e-7)
        assert (*np.asarray(new.agent_pos).tolist(), int(new.heading), int(new.horizon)) == after
        pose, state = after, new
    assert bool(terminated) and any(g > 0 for g in gains) and any(g < 0 for g in gains)


def test_replay_oracle_follows_the_reference_bfs_and_rooms(house_kit):
    """probes.replay_oracle (experiments.failures): an episode replayed from its reset key
    and actions gives, before each action, the reference BFS's actions to success and
    whether the agent stands in the target's room (the layout's own room map)."""
    from env_reference import reference_transition
    from experiments.analysis.probes import replay_oracle

    kit, rng = house_kit, np.random.default_rng(5)
    keys = jax.random.split(jax.random.key(11), 64)
    _, states = kit.reset_batch(keys)
    i = int(np.flatnonzero(np.asarray(states.scene) == 0)[0])  # an episode in the 2-room house 0
    state = jax.tree.map(lambda x: np.asarray(x)[i], states)
    dist, _ = reference_oracle(kit, 0)[0][int(state.target_slot)]
    layout = H.generate_house(int(kit.bank["numbers"][0]), "savn")
    target_room = layout.target_room[int(state.target)]
    actions = rng.integers(0, 5, 40)
    d, in_room = (
        np.asarray(x)[0] for x in replay_oracle(kit.env, kit.params, keys[i : i + 1], jnp.asarray(actions)[None])
    )
    pose = (*np.asarray(state.agent_pos).tolist(), int(state.heading), int(state.horizon))
    for t, action in enumerate(actions):
        assert d[t] == dist[pose] and in_room[t] == (layout.cell_room[pose[:2]] == target_room), t
        pose = reference_transition(kit.bank["cell_type"][0], pose, int(action))


@pytest.mark.slow
def test_config_progress_reward_reaches_the_training_env():
    from foresit_jax.config import Config
    from foresit_jax.train import make_env

    assert make_env(Config(method="a3c", layout="house", progress_reward=0.1))[1].progress_reward == 0.1
    assert make_env(Config(method="a3c"))[1].progress_reward == 0.0
    with pytest.raises(ValueError, match="progress_reward"):
        Config(progress_reward=-0.1)


def test_oracle_policy_scores_sr_1_and_spl_1(house_kit):
    np.testing.assert_array_equal(house_kit.params.max_steps, [HOUSE_EVAL_TIME_LIMIT] * 4)
    success, length, optimal, alive = house_kit.first_episodes(
        jax.random.split(jax.random.key(5), 1024), np.ones(1024, bool)
    )
    assert not alive.any() and success.all()
    np.testing.assert_array_equal(length, optimal)
    assert summarize(success, optimal / np.maximum(length, optimal), optimal)["SPL"] == 100.0


def test_calibration_long_paths_and_a_random_policy(house_kit):
    """4096 resets of the test houses: most need >= 10 actions (measured 81%), about 45%
    >= 20; a uniformly random policy (1024 episodes under the 300-step limit) succeeds in
    at most 3% (measured: see the assertion's message)."""
    kit = house_kit
    _, states = kit.reset_batch(jax.random.split(jax.random.key(0), 4096))
    length = states.optimal_length
    assert (length >= 10).mean() >= 0.7 and 0.3 <= (length >= 20).mean() <= 0.6, np.percentile(length, [10, 50, 90])
    assert length.min() >= 2 and np.percentile(length, 95) < HOUSE_EVAL_TIME_LIMIT / 4
    success, _, _, alive = kit.first_episodes(jax.random.split(jax.random.key(1), 1024), np.zeros(1024, bool))
    assert not alive.any() and success.mean() <= 0.03, success.mean()


def test_starts_are_away_from_the_target_room_in_the_documented_share(house_kit):
    """In a house, at least AWAY_SHARE (0.8, up to rounding) of each (house, target)'s start
    list lies in another room than the target's (more where the target's room has few
    valid starts), and about AWAY_SHARE of 4096 resets (measured 0.81)."""
    kit, b = house_kit, house_kit.bank
    grid = b["cell_type"].shape[1]
    rooms = b["cell_room"].reshape(len(b["numbers"]), -1)
    for s in range(len(b["numbers"])):
        for k in range(b["num_targets"][s]):
            start = b["starts"][s, k, : b["num_starts"][s, k]]
            away = (rooms[s, start // 8] >= 0) & (rooms[s, start // 8] != b["target_room"][s, k])
            assert away.mean() > B.AWAY_SHARE - 0.01 and len(np.unique(start)) == len(start)
    _, states = kit.reset_batch(jax.random.split(jax.random.key(2), 4096))
    cell = states.agent_pos[:, 0] * grid + states.agent_pos[:, 1]
    start_room = rooms[states.scene, cell]
    away = (start_room >= 0) & (start_room != b["target_room"][states.scene, states.target_slot])
    assert abs(away.mean() - B.AWAY_SHARE) < 0.03, away.mean()
    # info's room type is the target's room's.
    target_room = b["target_room"][states.scene, states.target_slot]
    np.testing.assert_array_equal(states.room_type, b["room_types"][states.scene, target_room])


def test_room_types_select_targets_by_their_room():
    env, params = envs.make("GridNav-v0", split="val", layout="house", room_types=["bathroom"], view_width=2)
    bank = jax.tree.map(np.asarray, vars(params.bank))
    assert all(C.BATHROOM in H.house_room_types(int(n)) for n in bank["numbers"])
    assert len(bank["numbers"]) == sum(C.BATHROOM in H.house_room_types(n) for n in C.house_numbers("val"))
    for s in range(len(bank["numbers"])):
        k = bank["num_targets"][s]
        assert (bank["room_types"][s, bank["target_room"][s, :k]] == C.BATHROOM).all()
        names = {C.categories("savn")[c] for c in bank["targets"][s, :k]}
        assert names == set(C.SAVN_TARGETS[C.BATHROOM])
    np.testing.assert_array_equal(
        envs.make(layout="house", view_width=2, split="val", training=True)[1].max_steps, [HOUSE_TRAIN_TIME_LIMIT] * 4
    )


def test_house_metrics_add_the_long_buckets():
    got = summarize([1, 0, 1, 1], [0.5, 0.0, 1.0, 0.25], [4, 12, 25, 9], LONG_PATH_MINS["house"])
    assert got["SR>=10"] == 50.0 and got["SPL>=10"] == 50.0 and got["episodes>=10"] == 2
    assert got["SR>=20"] == 100.0 and got["SPL>=20"] == 100.0 and got["episodes>=20"] == 1
    assert got["SR>=5"] == pytest.approx(200 / 3) and "SR>=10" not in summarize([1], [1.0], [3])


def test_render_places_the_agent_in_its_cell_of_a_house(house_kit):
    kit, cell_px = house_kit, 16
    scene = 14  # a 4-room house
    free = np.argwhere(kit.bank["cell_type"][scene] == C.CELL_FLOOR)
    pos = free[len(free) * 2 // 3]
    state = make_states(kit.bank, [scene], [0], pos[None], [3], [0])
    state = jax.tree.map(lambda x: x[0], state)
    rgb = render.render_topdown(kit.params, scene, state=state, decorations=False, cell_px=cell_px)
    pixels = np.argwhere((rgb == np.array(render.AGENT_RGB, np.uint8)).all(-1))
    assert len(pixels) > 0.1 * cell_px**2
    assert set(pixels[:, 0] // cell_px) == {pos[0]} and set(pixels[:, 1] // cell_px) == {pos[1]}
    assert rgb.shape[:2] == (30 * cell_px, 30 * cell_px)
    number = int(kit.bank["numbers"][scene])
    names = [C.ROOM_TYPES[t].replace("_", " ") for t in H.house_room_types(number)]
    assert render.scene_name(number, kit.bank["room_types"][scene]) == f"House{number} ({', '.join(names)})"
    assert render.scene_name(201, [1, -1, -1, -1]) == "FloorPlan201 (living room)"
    assert jnp.asarray(rgb).dtype == jnp.uint8


@pytest.mark.slow
def test_agents_train_and_evaluate_in_houses():
    """A tiny a3c+foresit trains 2 updates on houses (their bathrooms' targets) and is
    evaluated there: the house buckets are reported, every episode's room type is the
    bathroom, and an Evaluator of single rooms refuses a house config in one line."""
    import train_helpers as TH
    from envs.metrics import HOUSE_LENGTH_BUCKETS, bucket_label
    from foresit_jax.evaluate import Evaluator, agent_params
    from foresit_jax.train import Trainer

    config = TH.tiny_config("a3c+foresit", layout="house")
    env, env_params = envs.make("GridNav-v0", split="val", room_types=("bathroom",), layout="house", training=True)
    assert int(env_params.max_steps.max()) == HOUSE_TRAIN_TIME_LIMIT
    trainer = Trainer(config, env, env_params)
    state, metrics = jax.jit(trainer.run, static_argnums=2)(trainer.init(jax.random.PRNGKey(0)), env_params, 2)
    TH.assert_tree_finite(state)
    evaluator = Evaluator("savn", "house")
    results = evaluator.evaluate(
        agent_params(state, config.sigma2_max), config, "val", episodes_per_room=4, by_length=True
    )
    assert set(results) == {"bathroom", "overall", "by_length"}
    assert {"SR>=10", "SPL>=20", "episodes>=20"} <= set(results["overall"]) and results["overall"]["episodes"] == 4
    assert list(results["by_length"]) == [bucket_label(b) for b in HOUSE_LENGTH_BUCKETS]
    with pytest.raises(ValueError, match="layout 'room'.*layout='house'"):
        Evaluator("savn").evaluate(agent_params(state, config.sigma2_max), config, "val", episodes_per_room=4)


def test_the_house_preset_and_its_arms():
    from experiments.running.presets import preset, split_arm

    config, schedule = preset("house", "a3c")
    assert config.layout == "house" and schedule.test_episodes_per_room == 250 and config.progress_reward == 0.1
    assert preset("quick", "a3c")[0].progress_reward == 0.0  # the paper's reward in the single rooms
    assert preset("house", "a3c+maml")[0].num_steps == HOUSE_TRAIN_TIME_LIMIT  # whole house episodes
    assert preset("quick", "a3c+maml")[0].num_steps == 30
    with pytest.raises(ValueError, match="'layout' is not a Config field an arm can set"):
        split_arm("a3c@layout=house")
    with pytest.raises(ValueError, match="layout must be one of"):
        preset("quick", "a3c", layout="houses")


def test_reports_add_the_house_columns():
    from experiments.reporting import report, tables

    result = {
        "overall": {
            "SPL": 1.0,
            "SR": 2.0,
            "SPL>=5": 3.0,
            "SR>=5": 4.0,
            "SPL>=10": 5.0,
            "SR>=10": 6.0,
            "SPL>=20": None,
            "SR>=20": 8.0,
            "episodes": 4,
        }
    }
    md = tables.results_markdown(result, "T").splitlines()
    assert md[2] == "| rooms | SPL | SR | SPL>=5 | SR>=5 | SPL>=10 | SR>=10 | SPL>=20 | SR>=20 | episodes |"
    assert md[4] == "| overall | 1.00 | 2.00 | 3.00 | 4.00 | 5.00 | 6.00 | n/a | 8.00 | 4 |"
    lines = report.table_markdown(report.table({"a3c": [result] * 2}), "T").splitlines()
    assert lines[2] == "| Method | SPL | SR | SPL>=5 | SR>=5 | SPL>=10 | SR>=10 | SPL>=20 | SR>=20 |"
    assert lines[4].startswith("| a3c | 1.00 ± 0.00") and "| n/a | 8.00 ± 0.00" in lines[4]


def test_the_demo_checks_the_houses_own_calibration():
    from experiments import demo

    def checks(random_sr, long10, oracle_spl):
        results = {
            "random": {"overall": {"SR": random_sr}},
            "oracle": {"overall": {"SR": 100.0, "SPL": oracle_spl, "L^g>=10 %": long10}},
        }
        return [ok for _, ok in demo.calibration(results, "house")]

    assert checks(2.9, 70.0, 100.0) == [True, True, True]
    assert checks(3.1, 69.9, 99.9) == [False, False, False]
