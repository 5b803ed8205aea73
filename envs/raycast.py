"""The first-person view: ray casting over the grid, with occlusion and a camera horizon.

The agent stands at its cell centre.  ``view_width`` rays span a 100 degree field of view
around its heading.  Each ray walks the grid cell by cell (exact grid traversal: the cell
boundaries it crosses are computed in closed form and sorted) until a wall stops it.

Each view column has three rows (vertical bands).  A row looks at one height band over a
range of distances, which depends on the camera horizon, the way a pinhole camera's pixel
rows meet the floor, furniture tops and walls at different distances:

=========  ====================================  ====================================
row        horizon 0 (level)                     horizon 1 (30 degrees down)
=========  ====================================  ====================================
0 (top)    high band (wall objects), d >= 1.5    mid band (furniture tops), d >= 0
1          mid band (furniture tops), d >= 0     floor band, 2 <= d < 5
2 (bottom) floor band, 3 <= d < 8                floor band, 0 <= d < 2
=========  ====================================  ====================================

So objects on the floor close to the agent are seen only looking down, and objects high
on walls only looking level.  Occlusion: walls stop every row; furniture stops the mid and
floor rows; a floor object stops a floor row inside its window; a floor row that meets
nothing inside its window sees floor at its far edge.  Depths are in cells, rounded to
1/8 cell (the resolution of the precomputed view table) and at most ``MAX_DEPTH``
(255/8 = 31.9 cells, 8 m: the range of the depth camera; only a house's longest rays reach
it).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from envs import catalog as C

FIELD_OF_VIEW_DEG = 100.0
NUM_ROWS = 3
DEPTH_RESOLUTION = 8  # depth steps per cell
MAX_DEPTH = 255 / DEPTH_RESOLUTION  # cells: the depth camera's range (the table stores uint8 codes)
INF = 1e6
# [horizon, row] -> (height band, min distance, max distance), in cells.
ROW_BANDS = np.array([C.BAND_HIGH, C.BAND_MID, C.BAND_FLOOR, C.BAND_MID, C.BAND_FLOOR, C.BAND_FLOOR]).reshape(2, 3)
ROW_MIN_DIST = np.array([1.5, 0.0, 3.0, 0.0, 2.0, 0.0], np.float32).reshape(2, 3)
ROW_MAX_DIST = np.array([INF, INF, 8.0, INF, 5.0, 2.0], np.float32).reshape(2, 3)


def column_angles_deg(view_width: int) -> np.ndarray:
    """[W] offsets of the rays from the heading, left to right, in degrees."""
    step = FIELD_OF_VIEW_DEG / view_width
    return -FIELD_OF_VIEW_DEG / 2 + step * (np.arange(view_width) + 0.5)


def ray_cells(pos: jax.Array, angle_deg: jax.Array, grid_size: int):
    """The cells one ray enters and the distance at which it enters each, in no particular order.

    The ray leaves the centre of cell ``pos``; it enters a new cell at each grid line it
    crosses.  Crossing the i-th horizontal line (i = 0, 1, ...) moves it one row on, to
    row ``pos[0] + (i + 1) * sign(d_row)``, in the column where it crosses; likewise for
    vertical lines.  No sort is needed: the first cell that stops a view row is the one
    with the smallest entry distance among the cells that stop it.

    pos: int32 [2] (row, col); angle_deg: scalar, clockwise from north.
    Returns rows, cols: int32 [2G+2]; entry: float32 [2G+2] (cells).
    """
    phi = jnp.deg2rad(angle_deg)
    direction = jnp.stack([-jnp.cos(phi), jnp.sin(phi)])  # [2] (d_row, d_col)
    k = jnp.arange(grid_size + 1, dtype=jnp.float32) + 0.5
    inv = jnp.where(jnp.abs(direction) > 1e-9, 1.0 / jnp.maximum(jnp.abs(direction), 1e-9), INF)
    t_row, t_col = k * inv[0], k * inv[1]  # [G+1] crossing times of horizontal / vertical lines
    steps = jnp.arange(1, grid_size + 2, dtype=jnp.int32)
    sign = jnp.where(direction > 0, 1, -1).astype(jnp.int32)
    origin = pos.astype(jnp.float32) + 0.5
    cell = lambda x: jnp.clip(jnp.floor(x), -1, grid_size).astype(jnp.int32)  # noqa: E731 (no int overflow)
    rows = jnp.concatenate([pos[0] + sign[0] * steps, cell(origin[0] + t_col * direction[0])])
    cols = jnp.concatenate([cell(origin[1] + t_row * direction[1]), pos[1] + sign[1] * steps])
    entry = jnp.concatenate([t_row, t_col])
    return jnp.clip(rows, 0, grid_size - 1), jnp.clip(cols, 0, grid_size - 1), entry


def _first_hit(cell_t, cat, band, entry, row_band, lo, hi, furn_sem=None):
    """Category and depth one row sees along one ray ([K] arrays of the cells it enters).
    ``furn_sem`` ([K], layouts with priors) is the class each furniture cell shows; None:
    every piece shows as SEM_FURNITURE."""
    is_wall = cell_t == C.CELL_WALL
    is_furn = cell_t == C.CELL_FURNITURE
    in_window = (entry >= lo) & (entry < hi)
    obj_sem = C.NUM_STRUCTURAL + cat.astype(jnp.int32)
    shows_obj = (band == row_band) & in_window & (cat >= 0)
    floor_obj = (cell_t == C.CELL_OBJECT) & shows_obj
    floor_end = entry >= hi
    hit = jnp.where(
        row_band == C.BAND_HIGH,
        is_wall,
        jnp.where(row_band == C.BAND_MID, is_wall | is_furn, is_wall | is_furn | floor_obj | floor_end),
    )
    first = jnp.argmin(jnp.where(hit, entry, INF))  # the nearest cell that stops this row
    sem = jnp.where(
        is_wall[first],
        jnp.where(shows_obj[first], obj_sem[first], C.SEM_WALL),
        jnp.where(
            is_furn[first],
            jnp.where(shows_obj[first], obj_sem[first], C.SEM_FURNITURE if furn_sem is None else furn_sem[first]),
            jnp.where(floor_obj[first], obj_sem[first], C.SEM_FLOOR),
        ),
    )
    # A floor row whose first hit lies at or past its far edge sees floor there.
    past = entry[first] >= hi
    sem = jnp.where(past, C.SEM_FLOOR, sem)
    depth = jnp.where(past, hi, entry[first])
    return sem, depth


def view_rows(cell_t, cat, band, entry, row_band, lo, hi, furn_sem=None):
    """``_first_hit`` of every (view column, view row): the [W, K] cells the columns' rays
    enter (and ``furn_sem`` [W, K] or None), the rows' [3] bands and depth windows.
    Returns (sem, depth), each [W, 3]."""
    if furn_sem is None:  # the program as before layouts with priors existed
        per_row = jax.vmap(_first_hit, in_axes=(None, None, None, None, 0, 0, 0))  # rows
        per_col = jax.vmap(per_row, in_axes=(0, 0, 0, 0, None, None, None))  # columns
        return per_col(cell_t, cat, band, entry, row_band, lo, hi)
    per_row = jax.vmap(_first_hit, in_axes=(None, None, None, None, 0, 0, 0, None))
    per_col = jax.vmap(per_row, in_axes=(0, 0, 0, 0, None, None, None, 0))
    return per_col(cell_t, cat, band, entry, row_band, lo, hi, furn_sem)


def cast_view(cell_type, obj_cat, obj_band, pos, heading, horizon, view_width: int, furniture_sem=None):
    """Render the first-person view of one pose.

    cell_type, obj_cat, obj_band: int [G, G] (one scene); pos: int32 [2]; heading, horizon:
    int32 scalars; furniture_sem: int [G, G], the class each furniture cell shows (layouts
    with priors: ``catalog.furniture_sem`` of its kind), or None (SEM_FURNITURE).  Returns
    sem: int32 [3, W] semantic class per pixel (catalog.SEM_*, NUM_STRUCTURAL + category
    or a furniture kind's class); depth: float32 [3, W] in cells (1/8 cell resolution).
    """
    grid_size = cell_type.shape[0]
    angles = heading.astype(jnp.float32) * 45.0 + jnp.asarray(column_angles_deg(view_width), jnp.float32)
    rows, cols, entry = jax.vmap(lambda a: ray_cells(pos, a, grid_size))(angles)  # [W, K]
    cell_t, cat, band = cell_type[rows, cols], obj_cat[rows, cols], obj_band[rows, cols]
    furn = None if furniture_sem is None else furniture_sem[rows, cols]
    row_band = jnp.asarray(ROW_BANDS)[horizon]  # [3]
    lo = jnp.asarray(ROW_MIN_DIST)[horizon]
    hi = jnp.asarray(ROW_MAX_DIST)[horizon]
    sem, depth = view_rows(cell_t, cat, band, entry, row_band, lo, hi, furn)  # [W, 3]
    depth = jnp.minimum(jnp.round(depth * DEPTH_RESOLUTION), 255) / DEPTH_RESOLUTION
    return sem.T.astype(jnp.int32), depth.T.astype(jnp.float32)
