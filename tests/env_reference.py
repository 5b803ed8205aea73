"""Slow, independent references for the environment tests (plain Python / numpy).

Nothing here calls into ``envs`` except for the enum values of ``envs.catalog`` (cell
types, height bands, semantic classes, actions), so the tests compare the jitted
environment against code written from the specification (docs/design.md and the docstring of
``envs/raycast.py``), not against itself.

- ``reference_view``: the first-person view by marching each ray in tiny steps.
- ``reference_move`` / ``reference_transition``: the pose dynamics of the spec.
- ``bfs_distances``: shortest number of actions to success (Done counted) by a plain
  breadth-first search over (row, col, heading, horizon).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from envs import catalog as C

# --------------------------------------------------------------------------- spec facts
# Written out by hand from docs/design.md / the raycast docstring (not imported from envs).
FIELD_OF_VIEW_DEG = 100.0
# Heading 0 = north (row - 1), clockwise in 45 degree steps.
SPEC_DELTAS = ((-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1))
FLOOR_BAND, MID_BAND, HIGH_BAND = 0, 1, 2
# horizon -> [(height band, min distance, max distance)] for view rows 0 (top), 1, 2 (bottom).
ROW_TABLE = {
    0: [(HIGH_BAND, 1.5, math.inf), (MID_BAND, 0.0, math.inf), (FLOOR_BAND, 3.0, 8.0)],
    1: [(MID_BAND, 0.0, math.inf), (FLOOR_BAND, 2.0, 5.0), (FLOOR_BAND, 0.0, 2.0)],
}
WALL, FLOOR_CELL, FURNITURE, FLOOR_OBJECT = C.CELL_WALL, C.CELL_FLOOR, C.CELL_FURNITURE, C.CELL_OBJECT
SEM_WALL, SEM_FLOOR, SEM_FURNITURE, FIRST_CATEGORY = C.SEM_WALL, C.SEM_FLOOR, C.SEM_FURNITURE, C.NUM_STRUCTURAL
MOVE, LEFT, RIGHT, UP, DOWN, DONE = range(6)

assert (C.BAND_FLOOR, C.BAND_MID, C.BAND_HIGH) == (FLOOR_BAND, MID_BAND, HIGH_BAND)


def ray_angles_deg(heading: int, view_width: int) -> np.ndarray:
    """[W] absolute ray angles (clockwise from north), left to right across 100 degrees."""
    edges = np.linspace(-FIELD_OF_VIEW_DEG / 2, FIELD_OF_VIEW_DEG / 2, view_width + 1)
    return 45.0 * heading + 0.5 * (edges[:-1] + edges[1:])


# --------------------------------------------------------------------------- ray marching
def march_ray(cell_type, pos, angle_deg, step=0.002, max_dist=None):
    """Cells a ray enters, in order, with the distance (cells) at which it enters each.

    Marches from the centre of ``pos`` in steps of ``step`` cells and refines every
    change of cell by bisection (so cells whose corner the ray clips are found too).
    Stops after the first wall.  Returns a list of ((row, col), entry distance).
    """
    g = cell_type.shape[0]
    max_dist = 2.0 * g if max_dist is None else max_dist
    phi = math.radians(float(angle_deg))
    d_row, d_col = -math.cos(phi), math.sin(phi)
    r0, c0 = pos[0] + 0.5, pos[1] + 0.5

    def cell_at(t):
        return (math.floor(r0 + t * d_row), math.floor(c0 + t * d_col))

    ts = np.arange(1, int(max_dist / step) + 1) * step
    rows = np.floor(r0 + ts * d_row).astype(int)
    cols = np.floor(c0 + ts * d_col).astype(int)
    changes = np.flatnonzero((np.diff(rows) != 0) | (np.diff(cols) != 0)) + 1
    out = []
    current, t_prev = (int(pos[0]), int(pos[1])), 0.0
    for i in np.concatenate([[0], changes]):
        t_next = float(ts[i])
        target = (int(rows[i]), int(cols[i]))
        # Walk from `current` at t_prev to `target` at t_next, finding every cell between.
        while current != target:
            lo, hi = t_prev, t_next
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                if cell_at(mid) == current:
                    lo = mid
                else:
                    hi = mid
            current, t_prev = cell_at(hi), hi
            if not (0 <= current[0] < g and 0 <= current[1] < g):
                return out
            out.append((current, hi))
            if cell_type[current] == WALL:
                return out
        t_prev = t_next
    return out


def row_sees(ray, cell_type, obj_cat, obj_band, band, lo, hi, furniture_sem=None):
    """(semantic class, depth) one view row sees along one marched ray (raycast docstring);
    a piece of furniture shows as ``furniture_sem[r, c]`` when given (layouts with priors)."""
    for (r, c), d in ray:
        kind, cat, obj_b = cell_type[r, c], obj_cat[r, c], obj_band[r, c]
        in_window = lo <= d < hi
        shows_object = cat >= 0 and obj_b == band and in_window
        if band == FLOOR_BAND and d >= hi:
            # The floor row met nothing inside its window: floor at its far edge.
            return SEM_FLOOR, hi
        if kind == WALL:  # walls stop every row
            return (FIRST_CATEGORY + cat if shows_object else SEM_WALL), d
        if kind == FURNITURE and band in (MID_BAND, FLOOR_BAND):  # furniture stops mid and floor rows
            piece = SEM_FURNITURE if furniture_sem is None else int(furniture_sem[r, c])
            return (FIRST_CATEGORY + cat if shows_object else piece), d
        if kind == FLOOR_OBJECT and band == FLOOR_BAND and shows_object:  # inside its window
            return FIRST_CATEGORY + cat, d
    raise AssertionError("ray left the grid without meeting a wall")


def reference_view(cell_type, obj_cat, obj_band, pos, heading, horizon, view_width, step=0.002, furniture_sem=None):
    """sem int [3, W], depth float [3, W] (unrounded) and the minimum margin [3, W] between
    the entry distance of the cell each pixel ends on and any window edge (for ties)."""
    cell_type, obj_cat, obj_band = (np.asarray(a) for a in (cell_type, obj_cat, obj_band))
    sem = np.zeros((3, view_width), np.int64)
    depth = np.zeros((3, view_width), np.float64)
    margin = np.full((3, view_width), np.inf)
    for col, angle in enumerate(ray_angles_deg(int(heading), view_width)):
        ray = march_ray(cell_type, pos, angle, step)
        entries = np.array([d for _, d in ray])
        for row, (band, lo, hi) in enumerate(ROW_TABLE[int(horizon)]):
            sem[row, col], depth[row, col] = row_sees(ray, cell_type, obj_cat, obj_band, band, lo, hi, furniture_sem)
            edges = [e for e in (lo, hi) if np.isfinite(e)]
            if edges:
                margin[row, col] = np.min(np.abs(entries[:, None] - np.array(edges)[None, :]))
    return sem, depth, margin


# --------------------------------------------------------------------------- dynamics
def reference_move(cell_type, pos, heading):
    """MoveAhead: one step along the heading if the cell is free floor and, for a diagonal
    step, both cells it passes between are free floor too (no cutting corners)."""
    dr, dc = SPEC_DELTAS[heading]
    r, c = pos
    free = lambda rr, cc: cell_type[rr, cc] == FLOOR_CELL
    if not free(r + dr, c + dc):
        return (r, c)
    if dr != 0 and dc != 0 and not (free(r + dr, c) and free(r, c + dc)):
        return (r, c)
    return (r + dr, c + dc)


def reference_transition(cell_type, pose, action):
    """(row, col, heading, horizon) after one action (Done leaves the pose unchanged)."""
    r, c, h, z = pose
    if action == MOVE:
        r, c = reference_move(cell_type, (r, c), h)
    elif action == LEFT:
        h = (h + 7) % 8
    elif action == RIGHT:
        h = (h + 1) % 8
    elif action == UP:
        z = max(z - 1, 0)
    elif action == DOWN:
        z = min(z + 1, 1)
    return (r, c, h, z)


def pose_graph(cell_type):
    """Reversed edges of the pose graph over free cells: pose -> poses one action before it."""
    cell_type = np.asarray(cell_type)
    free = np.argwhere(cell_type == FLOOR_CELL)
    poses = [(int(r), int(c), h, z) for r, c in free for h in range(8) for z in range(2)]
    parents = {p: [] for p in poses}
    for p in poses:
        for a in (MOVE, LEFT, RIGHT, UP, DOWN):
            parents[reference_transition(cell_type, p, a)].append(p)
    return parents


def bfs_distances(cell_type, goal, parents=None):
    """Shortest number of actions to success (Done included) from every free-cell pose.

    cell_type: [G, G]; goal: dict or set of poses (row, col, heading, horizon) from which
    Done succeeds.  A plain forward BFS from each free pose would be slow, so this searches
    backwards from the goal poses over the reversed edges of the pose graph.  Returns a
    dict pose -> distance (absent = unreachable).  ``parents``: pose_graph(cell_type).
    """
    parents = pose_graph(cell_type) if parents is None else parents
    dist = {}
    queue = deque()
    for p in parents:
        if p in goal:
            dist[p] = 1
            queue.append(p)
    while queue:
        q = queue.popleft()
        for p in parents[q]:
            if p not in dist:
                dist[p] = dist[q] + 1
                queue.append(p)
    return dist


def bfs_forward(cell_type, start, goal):
    """Shortest number of actions (Done included) from one pose, by a forward BFS."""
    if start in goal:
        return 1
    seen = {start}
    queue = deque([(start, 1)])
    while queue:
        p, d = queue.popleft()
        for a in (MOVE, LEFT, RIGHT, UP, DOWN):
            q = reference_transition(cell_type, p, a)
            if q in seen:
                continue
            if q in goal:
                return d + 1
            seen.add(q)
            queue.append((q, d + 1))
    return None
