"""Scenes and catalog: numbering, splits, deterministic generation, room sizes, objects,
target encodings and detector features, and helpful errors."""

from collections import deque

import jax
import numpy as np
import pytest

import envs
from envs import catalog as C
from envs import scenes
from env_helpers import random_states

ROOMS = ("kitchen", "living_room", "bedroom", "bathroom")
FIRST_NUMBER = {"kitchen": 1, "living_room": 201, "bedroom": 301, "bathroom": 401}
ALL_NUMBERS = [FIRST_NUMBER[r] + i for r in ROOMS for i in range(30)]


@pytest.fixture(scope="module")
def layouts():
    """{(setup, number): Layout} for all 120 scenes and both setups (numpy, < 1 s)."""
    return {(s, n): scenes.generate_layout(n, s) for s in ("savn", "org") for n in ALL_NUMBERS}


def test_room_types_numbers_and_splits():
    assert C.ROOM_TYPES == ROOMS
    assert C.ACTIONS == ("MoveAhead", "RotateLeft", "RotateRight", "LookUp", "LookDown", "Done")
    expected = {"train": list(range(1, 21)), "val": [21, 23, 25, 27, 29], "test": [22, 24, 26, 28, 30]}
    every = []
    for split, layouts in expected.items():
        numbers = C.scene_numbers(split)
        assert numbers == [FIRST_NUMBER[r] - 1 + n for r in ROOMS for n in layouts], split
        every += numbers
    assert sorted(every) == sorted(ALL_NUMBERS), "the splits partition the 120 scenes"
    for r, room in enumerate(ROOMS):
        for i in range(30):
            assert C.room_type_of(FIRST_NUMBER[room] + i) == r
    assert C.scene_numbers("val", [C.BATHROOM]) == [421, 423, 425, 427, 429]


def test_bank_of_a_split_holds_its_scenes(savn_test, savn_val_narrow):
    _, params = savn_test
    expected = [FIRST_NUMBER[r] - 1 + n for r in ROOMS for n in (22, 24, 26, 28, 30)]
    np.testing.assert_array_equal(params.bank.numbers, expected)
    np.testing.assert_array_equal(params.bank.room_type, np.repeat(np.arange(4), 5))
    _, params = savn_val_narrow
    np.testing.assert_array_equal(params.bank.numbers, [221, 223, 225, 227, 229, 421, 423, 425, 427, 429])


def test_generation_is_deterministic(layouts):
    for number in (1, 230, 317, 424):
        for setup in ("savn", "org"):
            again = scenes.generate_layout(number, setup)
            first = layouts[(setup, number)]
            for name in ("cell_type", "obj_cat", "obj_band"):
                np.testing.assert_array_equal(getattr(again, name), getattr(first, name))
                assert getattr(again, name).dtype == np.int8
    # Different numbers give different rooms.
    walls = {layouts[("savn", n)].cell_type.tobytes() for n in ALL_NUMBERS}
    assert len(walls) == len(ALL_NUMBERS)


def test_savn_and_org_share_walls_and_furniture_but_place_objects_differently(layouts):
    for n in ALL_NUMBERS:
        savn, org = layouts[("savn", n)], layouts[("org", n)]
        structure = lambda layout: np.isin(layout.cell_type, [C.CELL_WALL, C.CELL_FURNITURE]) * layout.cell_type
        np.testing.assert_array_equal(structure(savn), structure(org), err_msg=str(n))
        assert (savn.cell_type == C.CELL_WALL).sum() == (org.cell_type == C.CELL_WALL).sum()
        assert not np.array_equal(savn.obj_cat >= 0, org.obj_cat >= 0), f"scene {n}: same object cells in both setups"


def interior_area(layout):
    """Cells inside the room (not wall)."""
    return int((layout.cell_type != C.CELL_WALL).sum())


def test_room_sizes_by_type(layouts):
    means = [np.mean([interior_area(layouts[("savn", FIRST_NUMBER[r] + i)]) for i in range(30)]) for r in ROOMS]
    kitchen, living, bedroom, bathroom = means
    assert bathroom < bedroom < kitchen < living, means
    for n in ALL_NUMBERS:
        assert layouts[("savn", n)].cell_type.shape == (20, 20)
        cell = layouts[("savn", n)].cell_type
        assert (cell[0] == C.CELL_WALL).all() and (cell[-1] == C.CELL_WALL).all()
        assert (cell[:, 0] == C.CELL_WALL).all() and (cell[:, -1] == C.CELL_WALL).all()


def test_every_free_cell_is_connected(layouts):
    for (setup, n), layout in layouts.items():
        free = layout.cell_type == C.CELL_FLOOR
        start = tuple(np.argwhere(free)[0])
        seen, queue = {start}, deque([start])
        while queue:
            r, c = queue.popleft()
            for nb in ((r + 1, c), (r - 1, c), (r, c + 1), (r, c - 1)):
                if free[nb] and nb not in seen:
                    seen.add(nb)
                    queue.append(nb)
        assert len(seen) == free.sum(), f"{setup} scene {n}: {free.sum() - len(seen)} free cells cut off"


def test_objects_stand_at_three_heights(layouts):
    bands_seen = {"savn": set(), "org": set()}
    for (setup, n), layout in layouts.items():
        names = C.categories(setup)
        cell, cat, band = layout.cell_type, layout.obj_cat, layout.obj_band
        np.testing.assert_array_equal(cat >= 0, band >= 0)

        def next_to(kinds):
            near = np.zeros_like(cell, bool)
            ok = np.isin(cell, kinds)
            near[1:] |= ok[:-1]
            near[:-1] |= ok[1:]
            near[:, 1:] |= ok[:, :-1]
            near[:, :-1] |= ok[:, 1:]
            return near

        # A ray can reach a mid object over floor or floor objects, a high one over anything but walls.
        approach = {
            C.BAND_FLOOR: next_to([C.CELL_FLOOR]),
            C.BAND_MID: next_to([C.CELL_FLOOR, C.CELL_OBJECT]),
            C.BAND_HIGH: next_to([C.CELL_FLOOR, C.CELL_OBJECT, C.CELL_FURNITURE]),
        }
        placed = []
        for r, c in np.argwhere(cat >= 0):
            name, b = names[cat[r, c]], band[r, c]
            placed.append(name)
            bands_seen[setup].add(int(b))
            assert b == C.category_band(name)
            stands_on = {C.BAND_FLOOR: C.CELL_OBJECT, C.BAND_MID: C.CELL_FURNITURE, C.BAND_HIGH: C.CELL_WALL}[b]
            assert cell[r, c] == stands_on, (setup, n, name)
            assert approach[b][r, c], f"{setup} scene {n}: no ray can reach {name}"
        assert (cell == C.CELL_OBJECT).sum() == sum(C.category_band(p) == C.BAND_FLOOR for p in placed)
        # One instance of every target category of the room type.
        assert sorted(placed) == sorted(C.SETUPS[setup][1][layout.room_type]), (setup, n)
    assert bands_seen == {"savn": {0, 1, 2}, "org": {0, 1, 2}}
    assert C.category_band("GarbageCan") == C.BAND_FLOOR
    assert C.category_band("Television") == C.BAND_HIGH
    assert C.category_band("Laptop") == C.BAND_MID


def test_setup_targets_as_in_the_design():
    assert C.SAVN_TARGETS == {
        C.KITCHEN: ("Toaster", "Microwave", "Fridge", "CoffeeMaker", "GarbageCan", "Box", "Bowl"),
        C.LIVING_ROOM: ("Pillow", "Laptop", "Television", "GarbageCan", "Box", "Bowl"),
        C.BEDROOM: ("HousePlant", "Lamp", "Book", "AlarmClock"),
        C.BATHROOM: ("Sink", "ToiletPaper", "SoapBottle", "LightSwitch"),
    }
    assert len(C.ORG_CATEGORIES) == 22 and len(set(C.ORG_CATEGORIES)) == 22
    for room, names in C.ORG_TARGETS.items():
        assert set(names) <= set(C.ORG_CATEGORIES), room
    assert C.SETUPS["savn"][2] == 1.0 and C.SETUPS["org"][2] == 1.5
    assert len(C.categories("savn")) == 18


def test_bank_targets_are_the_objects_present(savn_kit):
    bank = savn_kit.bank
    for s in range(bank["numbers"].shape[0]):
        k = int(bank["num_targets"][s])
        present = sorted(set(bank["obj_cat"][s][bank["obj_cat"][s] >= 0].tolist()))
        assert sorted(bank["targets"][s, :k].tolist()) == present
        assert (bank["targets"][s, k:] == -1).all()
        assert (bank["num_starts"][s, :k] > 0).all()


def test_savn_target_is_a_fixed_300d_word_vector(savn_kit):
    obs, states = savn_kit.reset_batch(jax.random.split(jax.random.key(0), 256))
    target, cat = obs["target"], states.target
    assert target.shape == (256, 300) and target.dtype == np.float32
    by_cat = {}
    for vec, c in zip(target, cat.tolist()):
        if c in by_cat:
            np.testing.assert_array_equal(vec, by_cat[c])  # same category, same vector
        by_cat[c] = vec
    assert len(by_cat) > 10
    vectors = np.stack(list(by_cat.values()))
    assert np.linalg.matrix_rank(vectors) == len(by_cat), "distinct categories need distinct vectors"
    assert np.all(np.std(vectors, axis=1) > 0.1)


def test_org_target_one_hot_and_detections(org_kit):
    kit = org_kit
    obs, states = kit.reset_batch(jax.random.split(jax.random.key(1), 64))
    assert obs["target"].shape == (64, 22)
    np.testing.assert_array_equal(obs["target"], np.eye(22, dtype=np.float32)[states.target])
    det = obs["detections"]
    assert det.shape == (64, 22, 7) and det.dtype == np.float32
    np.testing.assert_array_equal(det[..., 6], np.eye(22, dtype=np.float32)[states.target])
    # The other features against the view: visible flag and the box of each category.
    more = random_states(kit.bank, np.random.default_rng(3), 128)
    more_obs = kit.obs_batch(more)
    det = more_obs["detections"]
    sem = more_obs["view"][..., :-1].argmax(-1)  # [N, 3, W]
    depth = more_obs["view"][..., -1] * kit.env.max_depth
    w = kit.env.view_width
    checked = 0
    for i in range(128):
        for c in range(22):
            mask = sem[i] == C.NUM_STRUCTURAL + c
            if not mask.any():
                np.testing.assert_array_equal(det[i, c, :6], 0.0)
                continue
            checked += 1
            rows, cols = np.nonzero(mask)
            box = [1.0, cols.min() / w, (cols.max() + 1) / w, rows.min() / 3, (rows.max() + 1) / 3]
            np.testing.assert_allclose(det[i, c, :5], box, rtol=1e-6)
            assert 0 < det[i, c, 5] <= 1
        # Confidence falls with the distance of the nearest pixel.
        vis = [c for c in range(22) if det[i, c, 0] > 0]
        near = {c: depth[i][sem[i] == C.NUM_STRUCTURAL + c].min() for c in vis}
        for a in vis:
            for b in vis:
                if near[a] < near[b] - 1e-3:
                    assert det[i, a, 5] > det[i, b, 5]
    assert checked > 50


@pytest.mark.parametrize(
    "call, words",
    [
        (lambda: envs.make("GridNav-v9"), ["GridNav-v0"]),
        (lambda: envs.make(setup="habitat"), ["habitat", "savn", "org"]),
        (lambda: envs.make(split="training", room_types=["bathroom"]), ["training", "train", "val", "test"]),
        (lambda: envs.make(split="test", room_types=["garage"]), ["garage", "kitchen", "bathroom"]),
        (lambda: envs.make(split="test", room_types=[7]), ["0..3"]),
        (lambda: envs.GridNav(view_width=0), ["view_width"]),
        (lambda: scenes.generate_layout(31, "savn"), ["31", "201-230"]),
        (lambda: scenes.generate_layout(501, "savn"), ["501"]),
        (lambda: scenes.generate_layout(1, "savn", grid_size=10), ["grid_size", "20"]),
        (lambda: C.scene_numbers("dev"), ["dev", "train"]),
    ],
)
def test_bad_names_raise_helpful_value_errors(call, words):
    with pytest.raises(ValueError) as info:
        call()
    for word in words:
        assert word in str(info.value), (word, str(info.value))
