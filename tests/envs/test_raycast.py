"""The first-person view (envs.raycast.cast_view) against a slow ray-marching reference
of the semantics in the raycast docstring, on hand-made scenes and generated layouts."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import envs
from envs import catalog as C
from envs import raycast, scenes
from env_helpers import cast_views, random_states, to_numpy
from env_reference import reference_view

W = 16
CENTRE = [7, 8]  # the two middle columns of 16 look 3.125 degrees either side of the heading
SEM_OBJ = C.NUM_STRUCTURAL  # semantic class of category 0
LEVEL, DOWN = 0, 1


@functools.partial(jax.jit, static_argnames="view_width")
def cast(cell_type, obj_cat, obj_band, pos, heading, horizon, view_width=W):
    return raycast.cast_view(cell_type, obj_cat, obj_band, pos, heading, horizon, view_width)


def room(size=12):
    """An empty room: floor inside a one-cell border wall; no objects."""
    cell = np.full((size, size), C.CELL_WALL, np.int8)
    cell[1:-1, 1:-1] = C.CELL_FLOOR
    return cell, np.full((size, size), -1, np.int8), np.full((size, size), -1, np.int8)


def put(scene, rc, cell=None, cat=None, band=None):
    cell_type, obj_cat, obj_band = scene
    if cell is not None:
        cell_type[rc] = cell
    if cat is not None:
        obj_cat[rc], obj_band[rc] = cat, band


def view(scene, pos, heading, horizon, view_width=W):
    sem, depth = cast(
        *(jnp.asarray(a) for a in scene),
        jnp.asarray(pos, jnp.int32),
        jnp.int32(heading),
        jnp.int32(horizon),
        view_width=view_width,
    )
    return np.asarray(sem), np.asarray(depth)


def sees(sem, cat):
    return (sem == SEM_OBJ + cat).any()


# --------------------------------------------------------------------------- hand-made scenes
def test_wall_occludes_an_object():
    scene = room()
    put(scene, (5, 5), C.CELL_FURNITURE, cat=0, band=C.BAND_MID)  # 4 cells north of the agent
    sem, depth = view(scene, (9, 5), 0, LEVEL)
    assert (sem[1, CENTRE] == SEM_OBJ).all(), "control: the object is in plain view without the wall"
    np.testing.assert_allclose(depth[1, CENTRE], 3.5)
    for c in (4, 5, 6):
        put(scene, (7, c), C.CELL_WALL)  # a wall 2 cells north
    for horizon in (LEVEL, DOWN):
        sem, depth = view(scene, (9, 5), 0, horizon)
        assert not sees(sem, 0)
        assert (sem[:, CENTRE] == C.SEM_WALL).all(), "walls stop every row"
        np.testing.assert_allclose(depth[:, CENTRE], 1.5)


def test_furniture_occludes_a_floor_object_but_not_a_high_wall_object():
    scene = room()
    put(scene, (5, 5), C.CELL_OBJECT, cat=1, band=C.BAND_FLOOR)  # floor object 4 cells north
    put(scene, (0, 5), cat=2, band=C.BAND_HIGH)  # high on the north wall, 9 cells north
    sem, depth = view(scene, (9, 5), 0, LEVEL)
    assert (sem[2, CENTRE] == SEM_OBJ + 1).all(), "control: the floor object is seen by the level floor row"
    assert (sem[0, CENTRE] == SEM_OBJ + 2).all()
    put(scene, (7, 5), C.CELL_FURNITURE)  # furniture 2 cells north, in between
    sem, depth = view(scene, (9, 5), 0, LEVEL)
    assert not sees(sem[:, 6:10], 1), "furniture must hide the floor object behind it"
    assert (sem[2, CENTRE] == C.SEM_FURNITURE).all() and (sem[1, CENTRE] == C.SEM_FURNITURE).all()
    np.testing.assert_allclose(depth[1:, CENTRE], 1.5)
    assert (sem[0, CENTRE] == SEM_OBJ + 2).all(), "the high row looks over furniture at the wall object"
    np.testing.assert_allclose(depth[0, CENTRE], 8.5)


@pytest.mark.parametrize("cells_ahead, level_row, down_row", [(2, None, 2), (4, 2, 1), (7, 2, None)])
def test_floor_object_rows_depend_on_horizon_and_distance(cells_ahead, level_row, down_row):
    """Floor rows: level sees the floor at 3 <= d < 8 (bottom row); down sees 2 <= d < 5
    (middle row) and 0 <= d < 2 (bottom row).  A floor object entered at d = cells - 0.5."""
    scene = room()
    put(scene, (9 - cells_ahead, 5), C.CELL_OBJECT, cat=3, band=C.BAND_FLOOR)
    for horizon, row in ((LEVEL, level_row), (DOWN, down_row)):
        sem, depth = view(scene, (9, 5), 0, horizon)
        if row is None:
            assert not sees(sem, 3), (horizon, sem)
        else:
            assert (sem[row, CENTRE] == SEM_OBJ + 3).all(), (horizon, sem)
            np.testing.assert_allclose(depth[row, CENTRE], cells_ahead - 0.5)
            others = [r for r in range(3) if r != row]
            assert not sees(sem[others][:, CENTRE], 3)


def test_high_object_visible_level_but_not_down_nor_too_close():
    scene = room()
    put(scene, (0, 5), cat=4, band=C.BAND_HIGH)
    sem, depth = view(scene, (5, 5), 0, LEVEL)
    assert (sem[0, CENTRE] == SEM_OBJ + 4).all()
    np.testing.assert_allclose(depth[0, CENTRE], 4.5)
    assert (sem[1:, CENTRE] == C.SEM_WALL).all()  # the wall (4.5) is inside the floor row's window
    sem, _ = view(scene, (5, 5), 0, DOWN)
    assert not sees(sem, 4), "looking down never shows the high band"
    sem, depth = view(scene, (1, 5), 0, LEVEL)  # the wall 0.5 cells away: below 1.5, just wall
    assert not sees(sem, 4) and (sem[0, CENTRE] == C.SEM_WALL).all()


def test_mid_object_on_furniture_seen_by_the_mid_rows():
    scene = room()
    put(scene, (6, 5), C.CELL_FURNITURE, cat=5, band=C.BAND_MID)
    sem, depth = view(scene, (9, 5), 0, LEVEL)
    assert (sem[1, CENTRE] == SEM_OBJ + 5).all() and (sem[0, CENTRE] == C.SEM_WALL).all()
    assert (sem[2, CENTRE] == C.SEM_FURNITURE).all()  # furniture (2.5) stops the floor row before 3
    np.testing.assert_allclose(depth[1, CENTRE], 2.5)
    sem, depth = view(scene, (9, 5), 0, DOWN)
    assert (sem[0, CENTRE] == SEM_OBJ + 5).all() and (sem[1, CENTRE] == C.SEM_FURNITURE).all()
    np.testing.assert_allclose(depth[:2, CENTRE], 2.5)
    assert not sees(sem[1:], 5)


def test_floor_row_ends_on_floor_at_its_far_edge():
    """'A floor row that meets nothing inside its window sees floor at its far edge.'
    Looking down, the bottom row covers 0 <= d < 2: a wall 2.5 cells ahead is outside the
    window, so the row sees floor at depth 2 (a wall 3.5 ahead gives the same).  Level,
    the bottom row covers 3 <= d < 8: walls 8.5 and 9.5 ahead both give floor at 8."""
    scene = room()
    cases = (((4, 5), DOWN, 2.0), ((3, 5), DOWN, 2.0), ((10, 5), LEVEL, 8.0), ((9, 5), LEVEL, 8.0))
    for pos, horizon, far_edge in cases:
        sem, depth = view(scene, pos, 0, horizon)
        wall_at = pos[0] - 0.5
        assert (sem[2, CENTRE] == C.SEM_FLOOR).all(), f"wall {wall_at} ahead, horizon {horizon}: {sem[2, CENTRE]}"
        np.testing.assert_allclose(depth[2, CENTRE], far_edge, err_msg=f"wall {wall_at} ahead, horizon {horizon}")


def test_headings_rows_and_columns_are_not_swapped():
    """The view turns with the heading (0 north = row - 1, 2 east = col + 1, clockwise) and
    columns run left to right."""
    scene = room()
    put(scene, (5, 9), C.CELL_FURNITURE, cat=6, band=C.BAND_MID)  # due east of (5, 4)
    for heading in range(8):
        sem, depth = view(scene, (5, 4), heading, LEVEL)
        assert sees(sem, 6) == (heading in (1, 2, 3)), heading
    sem, depth = view(scene, (5, 4), 2, LEVEL)
    assert (sem[1, CENTRE] == SEM_OBJ + 6).all()
    np.testing.assert_allclose(depth[1, CENTRE], 4.5)
    # North-west of the agent: left half of the view when facing north, right half facing west.
    scene = room()
    put(scene, (4, 2), C.CELL_FURNITURE, cat=7, band=C.BAND_MID)
    cols = lambda sem: np.flatnonzero((sem == SEM_OBJ + 7).any(0))
    sem, _ = view(scene, (8, 6), 0, LEVEL)
    assert len(cols(sem)) and cols(sem).max() < W // 2
    sem, _ = view(scene, (8, 6), 6, LEVEL)
    assert len(cols(sem)) and cols(sem).min() >= W // 2


def test_depth_is_rounded_to_an_eighth_of_a_cell():
    layout = scenes.generate_layout(224, "savn")
    free = np.argwhere(layout.cell_type == C.CELL_FLOOR)[::7]
    n = len(free)
    grids = [np.repeat(a[None], n, 0) for a in (layout.cell_type, layout.obj_cat, layout.obj_band)]
    _, depth = cast_views(*grids, free, np.arange(n) % 8, np.arange(n) % 2, view_width=W)
    np.testing.assert_array_equal(depth * 8, np.round(depth * 8))
    assert depth.min() > 0 and depth.max() < 30


# --------------------------------------------------------------------------- generated layouts
def compare_with_reference(layout, pos, heading, horizon, view_width, rows):
    sem, depth = view((layout.cell_type, layout.obj_cat, layout.obj_band), pos, heading, horizon, view_width)
    grids = (layout.cell_type, layout.obj_cat, layout.obj_band)
    ref_sem, ref_depth, margin = reference_view(*grids, pos, heading, horizon, view_width)
    clear = margin > 1e-3  # pixels whose ray does not meet a window edge at a cell boundary
    for row in rows:
        ok = clear[row]
        where = f"scene {layout.number} pos {tuple(pos)} heading {heading} horizon {horizon} row {row}"
        np.testing.assert_array_equal(sem[row][ok], ref_sem[row][ok], err_msg=where)
        np.testing.assert_allclose(depth[row][ok], ref_depth[row][ok], atol=1 / 16 + 1e-4, err_msg=where)


pose_strategy = dict(
    number=st.sampled_from([1, 7, 22, 30, 203, 224, 230, 305, 326, 410, 428]),
    setup=st.sampled_from(["savn", "org"]),
    cell=st.integers(0, 10**6),
    heading=st.integers(0, 7),
    horizon=st.integers(0, 1),
    view_width=st.sampled_from([16, 12]),
)
REFERENCE_SETTINGS = settings(
    max_examples=30, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow]
)


def _pose(number, setup, cell):
    layout = scenes.generate_layout(number, setup)
    free = np.argwhere(layout.cell_type == C.CELL_FLOOR)
    return layout, free[cell % len(free)]


@given(**pose_strategy)
@REFERENCE_SETTINGS
def test_mid_and_high_rows_match_the_reference_on_generated_layouts(number, setup, cell, heading, horizon, view_width):
    layout, pos = _pose(number, setup, cell)
    rows = [0, 1] if horizon == LEVEL else [0]  # the rows that look at the mid or high band
    compare_with_reference(layout, pos, heading, horizon, view_width, rows)


@given(**pose_strategy)
@REFERENCE_SETTINGS
def test_floor_rows_match_the_reference_on_generated_layouts(number, setup, cell, heading, horizon, view_width):
    layout, pos = _pose(number, setup, cell)
    rows = [2] if horizon == LEVEL else [1, 2]
    compare_with_reference(layout, pos, heading, horizon, view_width, rows)


# --------------------------------------------------------------------------- in the environment
@pytest.mark.parametrize("kit_name", ["savn_kit", "org_kit"])
def test_precomputed_and_ray_cast_views_give_identical_observations(request, kit_name):
    kit = request.getfixturevalue(kit_name)
    env_cast, params_cast = envs.make(setup=kit.env.setup, split="test", precomputed_views=False)
    assert not env_cast.precomputed_views and kit.env.precomputed_views
    states = random_states(kit.bank, np.random.default_rng(7), 128)
    obs_table = kit.obs_batch(states)
    obs_cast = jax.jit(jax.vmap(env_cast.get_obs, in_axes=(0, None)))(states, params_cast)
    for name in obs_table:
        np.testing.assert_array_equal(obs_table[name], np.asarray(obs_cast[name]), err_msg=name)
    # And the semantic channels are those of a fresh ray cast of the layout.
    s = to_numpy(states)
    sem, _ = cast_views(
        kit.bank["cell_type"][s.scene],
        kit.bank["obj_cat"][s.scene],
        kit.bank["obj_band"][s.scene],
        s.agent_pos,
        s.heading,
        s.horizon,
        view_width=kit.env.view_width,
    )
    np.testing.assert_array_equal(obs_table["view"][..., :-1].argmax(-1), sem)


def test_pose_index_layout():
    g = 20
    pos = jnp.array([[3, 17], [0, 0], [19, 19]])
    heading, horizon = jnp.array([5, 0, 7]), jnp.array([1, 0, 1])
    idx = envs.pose_index(pos, heading, horizon, g)
    np.testing.assert_array_equal(idx, [((3 * g + 17) * 8 + 5) * 2 + 1, 0, g * g * 16 - 1])
    p, h, z = envs.pose_from_index(idx, g)
    np.testing.assert_array_equal(p, pos)
    np.testing.assert_array_equal(h, heading)
    np.testing.assert_array_equal(z, horizon)
