"""The scene bank: every layout of a split stacked into arrays, with its precomputed tables.

Built once per (setup, split, room types, sizes) and cached: the layouts (numpy), the
first-person view of every pose (ray cast, jitted, vmapped over poses), and the oracle:
for every (scene, target) the shortest number of actions to success from every pose,
counting Done (SAVN's node count), by breadth-first relaxation over the pose graph
(cell x heading x horizon), jitted.  It also lists each scene's valid targets and, for
each (scene, target), the start poses (free cell, any heading, horizon 0) from which the
target is reachable but not already solved.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from envs import catalog as C
from envs.raycast import DEPTH_RESOLUTION, NUM_ROWS, cast_view
from envs.scenes import generate_layout

UNREACHABLE = np.iinfo(np.int16).max


@struct.dataclass
class SceneBank:
    """All scenes of a split, padded to one grid size.  S scenes, P = G*G*8*2 poses."""

    numbers: jax.Array  # int32 [S] AI2-THOR scene numbers
    room_type: jax.Array  # int32 [S]
    cell_type: jax.Array  # int8 [S, G, G] catalog.CELL_*
    obj_cat: jax.Array  # int8 [S, G, G] category index, -1 for none
    obj_band: jax.Array  # int8 [S, G, G] catalog.BAND_*, -1 for none
    targets: jax.Array  # int32 [S, K] the scene's valid target categories, -1 padded
    num_targets: jax.Array  # int32 [S]
    view_sem: jax.Array  # int8 [S, P, 3, W] semantic class of each view pixel of each pose
    view_depth: jax.Array  # uint8 [S, P, 3, W] depth in 1/8 cells
    distance: jax.Array  # int16 [S, K, P] shortest number of actions to success (Done included)
    starts: jax.Array  # int32 [S, K, G*G*8] start poses (pose index // 2), valid ones first
    num_starts: jax.Array  # int32 [S, K]
    target_vectors: jax.Array  # float32 [n_categories, D] what the agent is given as target


def pose_index(pos, heading, horizon, grid_size: int):
    """Flat index of a pose: ((row * G + col) * 8 + heading) * 2 + horizon."""
    return ((pos[..., 0] * grid_size + pos[..., 1]) * C.NUM_HEADINGS + heading) * C.NUM_HORIZONS + horizon


def pose_from_index(index, grid_size: int):
    """Inverse of pose_index: (pos [..., 2], heading, horizon)."""
    horizon = index % C.NUM_HORIZONS
    rest = index // C.NUM_HORIZONS
    heading = rest % C.NUM_HEADINGS
    cell = rest // C.NUM_HEADINGS
    return jnp.stack([cell // grid_size, cell % grid_size], -1), heading, horizon


def move_ahead(walkable, pos, heading):
    """MoveAhead from ``pos``: the new position, unchanged when blocked.

    walkable: bool [G, G].  A diagonal step also needs both cells it passes between to be
    free (no cutting corners of walls or furniture).
    """
    delta = jnp.asarray(C.HEADING_DELTAS)[heading]
    target = pos + delta
    side_a = pos + delta * jnp.array([1, 0])
    side_b = pos + delta * jnp.array([0, 1])
    ok = walkable[target[0], target[1]] & walkable[side_a[0], side_a[1]] & walkable[side_b[0], side_b[1]]
    return jnp.where(ok, target, pos)


def transition(walkable, pos, heading, horizon, action):
    """The pose after ``action`` (Done leaves the pose unchanged)."""
    moved = move_ahead(walkable, pos, heading)
    pos = jnp.where(action == C.MOVE_AHEAD, moved, pos)
    heading = jnp.where(
        action == C.ROTATE_LEFT,
        (heading - 1) % C.NUM_HEADINGS,
        jnp.where(action == C.ROTATE_RIGHT, (heading + 1) % C.NUM_HEADINGS, heading),
    )
    horizon = jnp.where(
        action == C.LOOK_UP,
        jnp.maximum(horizon - 1, 0),
        jnp.where(action == C.LOOK_DOWN, jnp.minimum(horizon + 1, C.NUM_HORIZONS - 1), horizon),
    )
    return pos, heading, horizon


@functools.partial(jax.jit, static_argnames=("view_width",))
def _scene_views(cell_type, obj_cat, obj_band, view_width: int):
    grid_size = cell_type.shape[0]
    idx = jnp.arange(grid_size * grid_size * C.NUM_HEADINGS * C.NUM_HORIZONS)
    pos, heading, horizon = pose_from_index(idx, grid_size)
    cast = lambda p, h, z: cast_view(cell_type, obj_cat, obj_band, p, h, z, view_width)
    sem, depth = jax.vmap(cast)(pos, heading, horizon)  # [P, 3, W]
    depth_code = jnp.clip(jnp.round(depth * DEPTH_RESOLUTION), 0, 255)
    return sem.astype(jnp.int8), depth_code.astype(jnp.uint8)


@jax.jit
def _scene_next_poses(cell_type):
    """int32 [P, 5]: the pose after each movement action (all actions but Done)."""
    grid_size = cell_type.shape[0]
    walkable = cell_type == C.CELL_FLOOR
    idx = jnp.arange(grid_size * grid_size * C.NUM_HEADINGS * C.NUM_HORIZONS)
    pos, heading, horizon = pose_from_index(idx, grid_size)
    pos = jnp.clip(pos, 1, grid_size - 2)  # poses inside border walls never move out

    def after(action):
        p, h, z = jax.vmap(lambda p, h, z: transition(walkable, p, h, z, action))(pos, heading, horizon)
        return pose_index(p, h, z, grid_size)

    return jnp.stack([after(a) for a in range(C.DONE)], -1)


@jax.jit
def _distances(goal, next_poses):
    """Shortest action counts to success by synchronous relaxation (BFS layers).

    goal: bool [K, P] poses from which Done succeeds; next_poses: int32 [P, 5].
    Returns int32 [K, P]: 1 at goal poses (Done), 1 + min over moves elsewhere, or
    UNREACHABLE.
    """
    init = jnp.where(goal, 1, UNREACHABLE).astype(jnp.int32)

    def body(carry):
        dist, _ = carry
        best_next = jnp.min(dist[:, next_poses], axis=-1)  # [K, P]
        new = jnp.minimum(dist, jnp.minimum(best_next + 1, UNREACHABLE))
        return new, jnp.any(new != dist)

    dist, _ = jax.lax.while_loop(lambda c: c[1], body, (init, jnp.array(True)))
    return dist


@functools.lru_cache(maxsize=16)
def build_bank(setup: str, scene_numbers: tuple[int, ...], grid_size: int, view_width: int) -> dict:
    """Numpy arrays of a SceneBank (cached: building a split takes seconds)."""
    categories = C.categories(setup)
    radius_cells = C.SETUPS[setup][2] / C.CELL_SIZE_M
    layouts = [generate_layout(n, setup, grid_size) for n in scene_numbers]
    max_targets = max(len(C.SETUPS[setup][1][r]) for r in range(4))
    num_poses = grid_size * grid_size * C.NUM_HEADINGS * C.NUM_HORIZONS
    out = {k: [] for k in SceneBank.__dataclass_fields__ if k != "target_vectors"}
    for layout in layouts:
        sem, depth_code = _scene_views(layout.cell_type, layout.obj_cat, layout.obj_band, view_width)
        sem, depth_code = np.asarray(sem), np.asarray(depth_code)
        present = sorted({int(c) for c in layout.obj_cat[layout.obj_cat >= 0]})
        in_range = depth_code <= radius_cells * DEPTH_RESOLUTION  # [P, 3, W]
        goal = np.stack([((sem == C.NUM_STRUCTURAL + c) & in_range).any((1, 2)) for c in present])
        dist = np.asarray(_distances(goal, _scene_next_poses(layout.cell_type)))  # [K', P]
        # Start poses: free cell, any heading, horizon 0, reachable, not already solved.
        free = (layout.cell_type == C.CELL_FLOOR).reshape(-1)
        level = dist[:, 0::2]  # [K', G*G*8] horizon-0 poses
        ok = (level > 1) & (level < UNREACHABLE) & np.repeat(free, C.NUM_HEADINGS)[None, :]
        keep = [i for i in range(len(present)) if ok[i].any()]
        k = len(keep)
        targets = np.full(max_targets, -1, np.int32)
        targets[:k] = [present[i] for i in keep]
        distance = np.full((max_targets, num_poses), UNREACHABLE, np.int16)
        distance[:k] = dist[keep]
        starts = np.zeros((max_targets, num_poses // 2), np.int32)
        num_starts = np.zeros(max_targets, np.int32)
        for j, i in enumerate(keep):
            valid = np.flatnonzero(ok[i])
            starts[j, : len(valid)] = valid
            num_starts[j] = len(valid)
        if k == 0:
            raise RuntimeError(f"scene {layout.number} has no reachable target under setup {setup!r}")
        for name, value in (
            ("numbers", layout.number), ("room_type", layout.room_type), ("cell_type", layout.cell_type),
            ("obj_cat", layout.obj_cat), ("obj_band", layout.obj_band), ("targets", targets),
            ("num_targets", k), ("view_sem", sem), ("view_depth", depth_code), ("distance", distance),
            ("starts", starts), ("num_starts", num_starts),
        ):  # fmt: skip
            out[name].append(value)
    arrays = {name: np.stack(values) for name, values in out.items()}
    arrays["numbers"] = arrays["numbers"].astype(np.int32)
    arrays["room_type"] = arrays["room_type"].astype(np.int32)
    arrays["num_targets"] = arrays["num_targets"].astype(np.int32)
    arrays["target_vectors"] = C.target_encodings(setup)
    assert len(categories) == arrays["target_vectors"].shape[0]
    return arrays


def make_bank(setup: str, scene_numbers, grid_size: int, view_width: int) -> SceneBank:
    arrays = build_bank(setup, tuple(int(n) for n in scene_numbers), grid_size, view_width)
    return SceneBank(**{k: jnp.asarray(v) for k, v in arrays.items()})


__all__ = ["SceneBank", "NUM_ROWS", "build_bank", "make_bank", "pose_index", "pose_from_index", "transition"]
