"""envs.render: the pictures show what the state says (no row/column swaps), PNGs are written."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from envs import catalog as C
from envs import render

CELL_PX = 48

# Positions off the diagonal (a row/column swap moves the agent to another cell), every heading.
POSES = [((3, 15), 0), ((15, 3), 1), ((3, 15), 2), ((10, 4), 3), ((4, 10), 4), ((17, 2), 5), ((2, 17), 6), ((8, 13), 7)]


@pytest.fixture(scope="module")
def scene():
    """(env, params, a state of scene 0): the five test kitchens, 4 view columns (cheap to build)."""
    env, params = envs.make("GridNav-v0", setup="savn", split="test", room_types=["kitchen"], view_width=4)
    _, state = env.reset(jax.random.key(0), params)
    return env, params, state.replace(scene=jnp.int32(0), target=params.bank.targets[0, 0])


def agent_pixels(rgb):
    """int [N, 2] (y, x) of the pixels drawn in the agent's colour."""
    return np.argwhere((rgb == np.array(render.AGENT_RGB, np.uint8)).all(-1))


def test_agent_colour_is_unique(scene):
    env, params, _ = scene
    rgb = render.render_topdown(params, 0, decorations=False, cell_px=CELL_PX)
    assert len(agent_pixels(rgb)) == 0


@pytest.mark.parametrize("pos, heading", POSES)
def test_agent_drawn_in_its_cell_facing_its_heading(scene, pos, heading):
    env, params, state = scene
    state = state.replace(agent_pos=jnp.array(pos, jnp.int32), heading=jnp.int32(heading))
    rgb = render.render_topdown(params, 0, state=state, decorations=False, cell_px=CELL_PX)
    grid = params.bank.cell_type.shape[-1]
    assert rgb.shape == (grid * CELL_PX, grid * CELL_PX, 3)

    pixels = agent_pixels(rgb)
    assert len(pixels) > 0.1 * CELL_PX**2, "the agent is missing or tiny"
    row, col = pos
    drawn_rows, drawn_cols = np.unique(pixels[:, 0] // CELL_PX), np.unique(pixels[:, 1] // CELL_PX)
    assert (drawn_rows == [row]).all(), f"agent drawn in rows {drawn_rows}, state row {row}"
    assert (drawn_cols == [col]).all(), f"agent drawn in cols {drawn_cols}, state col {col}"
    centre = np.array(render.agent_pixel(state.agent_pos, CELL_PX))
    np.testing.assert_allclose(centre, [(row + 0.5) * CELL_PX, (col + 0.5) * CELL_PX])

    # The arrow's tip (the agent pixel farthest from the cell centre) points along the heading.
    offsets = pixels + 0.5 - centre  # (d_row, d_col) in pixels
    tip = offsets[np.argmax(np.hypot(offsets[:, 0], offsets[:, 1]))]
    directions = C.HEADING_DELTAS / np.hypot(C.HEADING_DELTAS[:, 0], C.HEADING_DELTAS[:, 1])[:, None]
    assert int(np.argmax(directions @ tip)) == heading


def test_cells_drawn_at_row_col(scene):
    """Every cell without an object is drawn in its cell type's colour at (row, col)."""
    env, params, _ = scene
    rgb = render.render_topdown(params, 0, decorations=False, labels=False, cell_px=CELL_PX)
    cell_type = np.asarray(params.bank.cell_type[0])
    obj_cat = np.asarray(params.bank.obj_cat[0])
    assert not np.array_equal(cell_type, cell_type.T)  # the check below can see a swap
    centres = rgb[CELL_PX // 2 :: CELL_PX, CELL_PX // 2 :: CELL_PX]  # [G, G, 3]
    expected = np.array([render.CELL_RGB[int(k)] for k in cell_type.reshape(-1)], np.uint8).reshape(centres.shape)
    plain = obj_cat < 0
    np.testing.assert_array_equal(centres[plain], expected[plain])


def test_pngs_written(scene, tmp_path):
    env, params, state = scene
    trajectory = np.array([[3, 15], [4, 14], [5, 14]])
    top = tmp_path / "sub" / "topdown.png"
    rgb = render.render_topdown(params, 0, state=state, trajectory=trajectory, path=top)
    assert rgb.dtype == np.uint8 and rgb.ndim == 3 and rgb.shape[-1] == 3
    view = tmp_path / "view.png"
    obs = env.get_obs(state, params)
    render.render_view(obs, env.categories, path=view, max_depth=env.max_depth)
    for path in (top, view):
        data = path.read_bytes()
        assert len(data) > 1000 and data[:8] == b"\x89PNG\r\n\x1a\n"


def test_view_image_shapes(scene):
    env, params, state = scene
    sem, depth = env.view(state, params)  # [3, W]
    image = render.view_image(sem, depth, env.num_categories)
    assert image.shape == (3, env.view_width, 3)
    assert image.min() >= 0.0 and image.max() <= 1.0
    rgb_pair = render.render_view((sem, depth), env.categories)
    rgb_obs = render.render_view(env.get_obs(state, params), env.categories, max_depth=env.max_depth)
    assert rgb_pair.dtype == np.uint8 and rgb_pair.shape == rgb_obs.shape and rgb_pair.shape[-1] == 3
    # The observation's one-hot channels decode to the same classes.
    obs_sem = np.argmax(np.asarray(env.get_obs(state, params)["view"])[..., :-1], -1)
    np.testing.assert_array_equal(obs_sem, np.asarray(sem))
