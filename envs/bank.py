"""The scene bank: every layout of a split stacked into arrays, with its precomputed tables.

Built once per (setup, split, room types, sizes) and cached: the layouts (numpy), the
first-person view of every pose (ray cast, jitted, vmapped over poses; each (cell, heading)
casts its rays once for both camera horizons), and the oracle:
for every (scene, target) the shortest number of actions to success from every pose,
counting Done (SAVN's node count), by breadth-first relaxation over the pose graph
(cell x heading x horizon), jitted.  It also lists each scene's valid targets and, for
each (scene, target), the start poses (free cell, any heading, horizon 0) from which the
target is reachable but not already solved.  In a house (envs.houses) the start list is
weighted so that ``AWAY_SHARE`` of a uniform draw from it (or more, where the target's
room has few valid starts) starts in another room than the target's (all such poses, then
a fixed random subset of the rest); a single room's is every such pose.

Caching: a built bank is kept in memory (``build_bank`` is lru-cached) and on disk
(``envs.bank_cache``).
"""

from __future__ import annotations

import functools
import zlib

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from envs import bank_cache as cache
from envs import catalog as C
from envs.dynamics import pose_from_index, pose_index, transition
from envs.raycast import (
    DEPTH_RESOLUTION,
    NUM_ROWS,
    ROW_BANDS,
    ROW_MAX_DIST,
    ROW_MIN_DIST,
    column_angles_deg,
    ray_cells,
    view_rows,
)
from envs.houses import generate_house
from envs.priors import target_encodings as prior_target_encodings
from envs.scenes import generate_layout

UNREACHABLE = np.iinfo(np.int16).max
AWAY_SHARE = 0.8  # houses: the share of start poses in another room than the target's
MAX_ROOMS = max(C.HOUSE_SIZES)
ALL_ROOM_TYPES = tuple(range(len(C.ROOM_TYPES)))


@struct.dataclass
class SceneBank:
    """All scenes of a split, padded to one grid size.  S scenes, P = G*G*8*2 poses."""

    numbers: jax.Array  # int32 [S] AI2-THOR scene numbers or house numbers
    room_type: jax.Array  # int32 [S] a single room's type; -1 for a house (see room_types)
    cell_type: jax.Array  # int8 [S, G, G] catalog.CELL_*
    obj_cat: jax.Array  # int8 [S, G, G] category index, -1 for none
    obj_band: jax.Array  # int8 [S, G, G] catalog.BAND_*, -1 for none
    cell_room: jax.Array  # int8 [S, G, G] the room index of each cell (0 in a single room), -1 for none
    room_types: jax.Array  # int32 [S, MAX_ROOMS] the room type of each room index, -1 padded
    target_room: jax.Array  # int32 [S, K] the room index holding each target, -1 padded
    targets: jax.Array  # int32 [S, K] the scene's valid target categories, -1 padded
    num_targets: jax.Array  # int32 [S]
    view_sem: jax.Array  # int8 [S, P, 3, W] semantic class of each view pixel of each pose
    view_depth: jax.Array  # uint8 [S, P, 3, W] depth in 1/8 cells
    distance: jax.Array  # int16 [S, K, P] shortest number of actions to success (Done included)
    starts: jax.Array  # int32 [S, K, G*G*8] start poses (pose index // 2), valid ones first
    num_starts: jax.Array  # int32 [S, K]
    target_vectors: jax.Array  # float32 [n_categories, D] what the agent is given as target
    # int8 [S, G, G] the semantic class each furniture cell shows (layouts with priors, else
    # None: no array, and the program of today's layouts stays as it was)
    furniture_sem: jax.Array | None = None


@functools.partial(jax.jit, static_argnames=("view_width",))
def _scene_views(cell_type, obj_cat, obj_band, view_width: int, furniture_sem=None):
    """The view of every pose of one scene: (sem int8 [P, 3, W], depth code uint8 [P, 3, W]);
    ``furniture_sem`` as ``raycast.cast_view`` takes it.

    Equal, pixel for pixel, to ``raycast.cast_view`` of each pose (tests check it), but the
    rays of a (cell, heading) are cast and their cells gathered once for both horizons (the
    horizon only changes which band and depth window each view row looks at): 1.6x faster.
    """
    grid_size = cell_type.shape[0]
    idx = jnp.arange(grid_size * grid_size * C.NUM_HEADINGS)  # (row * G + col) * 8 + heading
    heading = idx % C.NUM_HEADINGS
    cell = idx // C.NUM_HEADINGS
    pos = jnp.stack([cell // grid_size, cell % grid_size], -1)
    offsets = jnp.asarray(column_angles_deg(view_width), jnp.float32)

    def cast(p, h):  # as cast_view, for horizons 0 and 1 at once
        angles = h.astype(jnp.float32) * 45.0 + offsets
        rows, cols, entry = jax.vmap(lambda a: ray_cells(p, a, grid_size))(angles)  # [W, K]
        cell_t, cat, band = cell_type[rows, cols], obj_cat[rows, cols], obj_band[rows, cols]
        furn = None if furniture_sem is None else furniture_sem[rows, cols]

        def at_horizon(z):
            row_band, lo, hi = (jnp.asarray(t)[z] for t in (ROW_BANDS, ROW_MIN_DIST, ROW_MAX_DIST))
            sem, depth = view_rows(cell_t, cat, band, entry, row_band, lo, hi, furn)  # [W, 3]
            depth = jnp.round(depth * DEPTH_RESOLUTION) / DEPTH_RESOLUTION
            return sem.T, depth.T  # [3, W]

        return jax.vmap(at_horizon)(jnp.arange(C.NUM_HORIZONS))  # [2, 3, W]

    sem, depth = jax.vmap(cast)(pos, heading)  # [G*G*8, 2, 3, W]: pose = that index * 2 + horizon
    sem = sem.reshape(-1, NUM_ROWS, view_width)
    depth = depth.reshape(-1, NUM_ROWS, view_width)
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


def _expected_arrays(setup: str, scene_numbers, grid_size: int, view_width: int, priors: bool = False) -> dict:
    """name -> (shape, dtype) of every array of a bank."""
    s, g, k = len(scene_numbers), grid_size, _max_targets(setup, scene_numbers)
    p = g * g * C.NUM_HEADINGS * C.NUM_HORIZONS
    i8, i32 = np.dtype(np.int8), np.dtype(np.int32)
    furniture = {"furniture_sem": ((s, g, g), i8)} if priors else {}
    return furniture | {
        "numbers": ((s,), i32),
        "room_type": ((s,), i32),
        "cell_type": ((s, g, g), i8),
        "obj_cat": ((s, g, g), i8),
        "obj_band": ((s, g, g), i8),
        "cell_room": ((s, g, g), i8),
        "room_types": ((s, MAX_ROOMS), i32),
        "target_room": ((s, k), i32),
        "targets": ((s, k), i32),
        "num_targets": ((s,), i32),
        "view_sem": ((s, p, NUM_ROWS, view_width), i8),
        "view_depth": ((s, p, NUM_ROWS, view_width), np.dtype(np.uint8)),
        "distance": ((s, k, p), np.dtype(np.int16)),
        "starts": ((s, k, p // 2), i32),
        "num_starts": ((s, k), i32),
        "target_vectors": ((len(C.categories(setup)), C.target_encodings(setup).shape[1]), np.dtype(np.float32)),
    }


def _max_targets(setup: str, scene_numbers) -> int:
    """K: a single room's most targets, or (with a house among the scenes) every category."""
    if any(C.is_house(n) for n in scene_numbers):
        return len(C.categories(setup))
    return max(len(C.SETUPS[setup][1][r]) for r in range(4))


@functools.lru_cache(maxsize=16)
def build_bank(
    setup: str,
    scene_numbers: tuple[int, ...],
    grid_size: int,
    view_width: int,
    target_rooms: tuple[int, ...] = ALL_ROOM_TYPES,
    priors: bool = False,
) -> dict:
    """Numpy arrays of a SceneBank, cached in memory and on disk (see the module doc).

    The first build of a split takes seconds (all four room types of the train split: about
    10 s on one CPU core); loading it from the disk cache takes a fraction of a second."""
    args = (setup, scene_numbers, grid_size, view_width, target_rooms, priors)
    path = cache.bank_cache_path(*args)
    if path is None:
        return compute_bank(*args)
    key = cache.bank_cache_key(*args)
    arrays = cache.load(path, key, _expected_arrays(setup, scene_numbers, grid_size, view_width, priors))
    if arrays is None:
        arrays = compute_bank(*args)
        cache.save(path, key, arrays)
    return arrays


def generate_scene(number: int, setup: str, grid_size: int, priors: bool = False):
    """The layout of a single room (an AI2-THOR number) or of a house (envs.houses), with
    the priors of real homes or without (envs.priors)."""
    return (generate_house if C.is_house(number) else generate_layout)(number, setup, grid_size, priors)


def compute_bank(
    setup: str,
    scene_numbers: tuple[int, ...],
    grid_size: int,
    view_width: int,
    target_rooms: tuple[int, ...] = ALL_ROOM_TYPES,
    priors: bool = False,
) -> dict:
    """Numpy arrays of a SceneBank, built from scratch (no cache).  A scene's targets are the
    categories present in it whose room has a type in ``target_rooms``."""
    categories = C.categories(setup)
    radius_cells = C.SETUPS[setup][2] / C.CELL_SIZE_M
    max_targets = _max_targets(setup, scene_numbers)
    out = {k: [] for k in SceneBank.__dataclass_fields__ if k != "target_vectors" and (priors or k != "furniture_sem")}
    for number in scene_numbers:
        layout = generate_scene(number, setup, grid_size, priors)
        furniture_sem = None
        if priors:
            furniture_sem = np.where(
                layout.furniture >= 0, C.furniture_sem(setup, 0) + layout.furniture, C.SEM_FURNITURE
            ).astype(np.int8)
            out["furniture_sem"].append(furniture_sem)
        sem, depth_code = _scene_views(layout.cell_type, layout.obj_cat, layout.obj_band, view_width, furniture_sem)
        sem, depth_code = np.asarray(sem), np.asarray(depth_code)
        present = sorted(c for c, room in layout.target_room.items() if layout.room_types[room] in target_rooms)
        in_range = depth_code <= radius_cells * DEPTH_RESOLUTION  # [P, 3, W]
        goal = np.stack([((sem == C.NUM_STRUCTURAL + c) & in_range).any((1, 2)) for c in present])
        dist = np.asarray(_distances(goal, _scene_next_poses(layout.cell_type)))  # [K', P]
        # Start poses: free cell, any heading, horizon 0, reachable, not already solved.
        free = (layout.cell_type == C.CELL_FLOOR).reshape(-1)
        level = dist[:, 0::2]  # [K', G*G*8] horizon-0 poses
        ok = (level > 1) & (level < UNREACHABLE) & np.repeat(free, C.NUM_HEADINGS)[None, :]
        keep = [i for i in range(len(present)) if ok[i].any()]
        if not keep:
            raise RuntimeError(f"scene {layout.number} has no reachable target under setup {setup!r}")
        k = len(keep)
        targets = np.full(max_targets, -1, np.int32)
        targets[:k] = [present[i] for i in keep]
        target_room = np.full(max_targets, -1, np.int32)
        target_room[:k] = [layout.target_room[present[i]] for i in keep]
        distance = np.full((max_targets, num_poses := dist.shape[1]), UNREACHABLE, np.int16)
        distance[:k] = dist[keep]
        starts = np.zeros((max_targets, num_poses // 2), np.int32)
        num_starts = np.zeros(max_targets, np.int32)
        room_of_start = np.repeat(layout.cell_room.reshape(-1), C.NUM_HEADINGS)
        for j, i in enumerate(keep):
            valid = _start_poses(ok[i], room_of_start, target_room[j], (setup, layout.number, j))
            starts[j, : len(valid)] = valid
            num_starts[j] = len(valid)
        room_types = np.full(MAX_ROOMS, -1, np.int32)
        room_types[: len(layout.room_types)] = layout.room_types
        for name, value in (
            ("numbers", layout.number),
            ("room_type", layout.room_type),
            ("cell_type", layout.cell_type),
            ("obj_cat", layout.obj_cat),
            ("obj_band", layout.obj_band),
            ("cell_room", layout.cell_room),
            ("room_types", room_types),
            ("target_room", target_room),
            ("targets", targets),
            ("num_targets", k),
            ("view_sem", sem),
            ("view_depth", depth_code),
            ("distance", distance),
            ("starts", starts),
            ("num_starts", num_starts),
        ):
            out[name].append(value)
    arrays = {name: np.stack(values) for name, values in out.items()}
    arrays["numbers"] = arrays["numbers"].astype(np.int32)
    arrays["room_type"] = arrays["room_type"].astype(np.int32)
    arrays["num_targets"] = arrays["num_targets"].astype(np.int32)
    arrays["target_vectors"] = prior_target_encodings(setup) if priors else C.target_encodings(setup)
    assert len(categories) == arrays["target_vectors"].shape[0]
    return arrays


def _start_poses(ok, room_of_start, target_room: int, seed) -> np.ndarray:
    """The start list of one (scene, target) from the valid start poses ``ok`` [G*G*8]: the
    poses in another room than the target's (``room_of_start`` >= 0, != ``target_room``),
    then as many of the others, a fixed random subset, as make them ``1 - AWAY_SHARE`` of
    the list (all of them where there are fewer); every valid pose, in order, when none
    is away (a single room)."""
    away = ok & (room_of_start >= 0) & (room_of_start != target_room)
    if not away.any():
        return np.flatnonzero(ok)
    near = np.flatnonzero(ok & ~away)
    wanted = int(round(away.sum() * (1 - AWAY_SHARE) / AWAY_SHARE))
    if len(near) > wanted:
        rng = np.random.default_rng(zlib.crc32(repr(seed).encode()))
        near = np.sort(rng.choice(near, wanted, replace=False))
    return np.concatenate([np.flatnonzero(away), near])


def make_bank(
    setup: str, scene_numbers, grid_size: int, view_width: int, target_rooms=ALL_ROOM_TYPES, priors: bool = False
) -> SceneBank:
    scene_numbers = tuple(int(n) for n in scene_numbers)
    arrays = build_bank(setup, scene_numbers, grid_size, view_width, tuple(int(r) for r in target_rooms), bool(priors))
    return SceneBank(**{k: jnp.asarray(v) for k, v in arrays.items()})


__all__ = ["AWAY_SHARE", "SceneBank", "NUM_ROWS", "build_bank", "compute_bank", "generate_scene", "make_bank"]
