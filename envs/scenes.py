"""Procedural but fixed scene layouts, one per AI2-THOR scene number (numpy, host side).

A layout is a padded ``[G, G]`` grid of cell types (floor, wall, furniture, floor object)
plus an object layer (category index and height band per cell).  The walls, room size and
furniture depend only on the scene number; the object placements depend on the scene
number and the setup (``savn`` and ``org`` place their objects differently, as the two
AI2-THOR configurations do).  With ``priors`` (envs.priors) the same walls are furnished
with pieces of distinct kinds and every object is placed by its relation.  Generation is
deterministic: the same number always gives the same scene.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from envs import catalog as C
from envs import priors as P
from envs.grid import next_to, walkable_connected

# Interior size ranges (rows, cols) in 0.25 m cells, by room type: bathrooms smallest,
# living rooms largest.
ROOM_SIZE_RANGES = {
    C.KITCHEN: ((10, 13), (11, 14)),
    C.LIVING_ROOM: ((13, 16), (14, 18)),
    C.BEDROOM: ((9, 11), (10, 12)),
    C.BATHROOM: ((6, 8), (7, 9)),
}
MIN_GRID_SIZE = 20  # the largest living room (16 x 18 interior) plus its walls

# Furniture pieces by room type: (rows, cols, against_wall).  Pieces are tried in order
# (random orientation and place); a piece that would cut the floor in two is skipped.
FURNITURE = {
    C.KITCHEN: [(1, 5, True), (1, 4, True), (1, 4, True), (1, 3, True), (2, 3, False), (1, 2, False)],
    C.LIVING_ROOM: [
        (1, 4, True),
        (2, 2, False),
        (1, 3, True),
        (1, 2, False),
        (1, 1, False),
        (1, 2, True),
        (2, 3, False),
    ],
    C.BEDROOM: [(3, 2, True), (1, 1, True), (1, 3, True), (1, 2, True), (1, 1, False)],
    C.BATHROOM: [(1, 3, True), (1, 2, True), (1, 1, True)],
}


@dataclass(frozen=True)
class Layout:
    """One generated scene (numpy arrays, row-major ``[row, col]``): a single room or a house."""

    number: int  # AI2-THOR scene number (rooms) or house number (envs.houses)
    room_type: int  # catalog.KITCHEN ... of a single room; -1 for a house (see room_types)
    cell_type: np.ndarray  # int8 [G, G], catalog.CELL_*
    obj_cat: np.ndarray  # int8 [G, G], category index in the setup's list, -1 for none
    obj_band: np.ndarray  # int8 [G, G], catalog.BAND_*, -1 for none
    cell_room: np.ndarray  # int8 [G, G], index of the room a cell lies in (0 in a single room), -1 for none
    room_types: tuple[int, ...]  # the room type of each room index
    target_room: dict  # category index -> index of the room its (one) instance belongs to
    furniture: np.ndarray | None = None  # int8 [G, G] furniture kind per cell, -1 for none (priors only)


def _rng(*parts) -> np.random.Generator:
    return np.random.default_rng(zlib.crc32("/".join(map(str, parts)).encode()))


def generate_layout(number: int, setup: str, grid_size: int = MIN_GRID_SIZE, priors: bool = False) -> Layout:
    """The scene with AI2-THOR number ``number`` under ``setup``'s object placements; with
    ``priors``, the same walls furnished with kinds and filled by relations (envs.priors)."""
    room = C.room_type_of(number)
    C.check_setup(setup)
    if grid_size < MIN_GRID_SIZE:
        raise ValueError(f"grid_size must be at least {MIN_GRID_SIZE}, got {grid_size}")
    rng = _rng("layout", number)
    (r_lo, r_hi), (c_lo, c_hi) = ROOM_SIZE_RANGES[room]
    rows, cols = rng.integers(r_lo, r_hi + 1), rng.integers(c_lo, c_hi + 1)
    if rng.random() < 0.5:
        rows, cols = cols, rows
    rows, cols = min(rows, grid_size - 2), min(cols, grid_size - 2)
    top = rng.integers(1, grid_size - rows)  # interior starts at row `top`
    left = rng.integers(1, grid_size - cols)
    cell = np.full((grid_size, grid_size), C.CELL_WALL, np.int8)
    cell[top : top + rows, left : left + cols] = C.CELL_FLOOR

    if room == C.LIVING_ROOM:  # a partition with a doorway: long trajectories
        if rows >= cols:
            r = top + rows // 2 + rng.integers(-2, 3)
            door = left + rng.integers(0, cols - 2)
            cell[r, left : left + cols] = C.CELL_WALL
            cell[r, door : door + 3] = C.CELL_FLOOR
        else:
            c = left + cols // 2 + rng.integers(-2, 3)
            door = top + rng.integers(0, rows - 2)
            cell[top : top + rows, c] = C.CELL_WALL
            cell[door : door + 3, c] = C.CELL_FLOOR

    if priors:
        cell, furniture = P.furnish_with_kinds(
            cell, np.full(cell.shape, -1, np.int8), room, rng, (top, left, rows, cols)
        )
    else:
        cell, furniture = furnish(cell, room, rng, (top, left, rows, cols)), None
    obj_cat = np.full(cell.shape, -1, np.int8)
    obj_band = np.full(cell.shape, -1, np.int8)
    interior = np.zeros(cell.shape, bool)
    interior[1:-1, 1:-1] = True
    rng = _rng("priors-objects" if priors else "objects", setup, number)
    cell, placed = place_objects(
        cell, obj_cat, obj_band, setup, C.SETUPS[setup][1][room], rng, interior, furniture=furniture
    )
    cell_room = np.where(_rect_mask(cell.shape, (top, left, rows, cols)) & (cell != C.CELL_WALL), 0, -1)
    return Layout(
        number, room, cell, obj_cat, obj_band, cell_room.astype(np.int8), (room,), dict.fromkeys(placed, 0), furniture
    )


def _rect_mask(shape, rect) -> np.ndarray:
    top, left, rows, cols = rect
    mask = np.zeros(shape, bool)
    mask[top : top + rows, left : left + cols] = True
    return mask


def furnish(cell: np.ndarray, room: int, rng: np.random.Generator, rect, keep_free=None) -> np.ndarray:
    """``cell`` with room type ``room``'s furniture placed inside ``rect`` = (top, left, rows,
    cols): each piece tried in turn, at random orientations and places, skipped when it
    would cut the walkable floor (of the whole grid) in two or cover a cell of
    ``keep_free`` (bool [G, G], optional)."""
    top, left, rows, cols = rect
    for h, w, against_wall in FURNITURE[room]:
        if rng.random() < 0.5:
            h, w = w, h
        for _ in range(30):
            r = rng.integers(top, top + rows - h + 1)
            c = rng.integers(left, left + cols - w + 1)
            block = cell[r : r + h, c : c + w]
            if (block != C.CELL_FLOOR).any() or (keep_free is not None and keep_free[r : r + h, c : c + w].any()):
                continue
            ring = cell[r - 1 : r + h + 1, c - 1 : c + w + 1]
            if against_wall and not (ring == C.CELL_WALL).any():
                continue
            trial = cell.copy()
            trial[r : r + h, c : c + w] = C.CELL_FURNITURE
            if walkable_connected(trial):
                cell = trial
                break
    return cell


def place_objects(cell, obj_cat, obj_band, setup, names, rng, region, elsewhere=None, keep_free=None, furniture=None):
    """Place one instance of each category in ``names`` inside ``region`` (bool [G, G]):
    floor objects on free floor of the region (never cutting the walkable floor in two),
    mid objects on the region's furniture next to floor, high objects on walls next to the
    region's floor and, when ``elsewhere`` (the floor of other rooms) is given, not next to
    it (an object hangs on one face of a wall: seen from one room only); no floor object on
    a cell of ``keep_free``.  With ``furniture`` (the kinds of a layout with priors), the
    most constrained categories go first (``priors.placement_order``) and each object's
    candidates narrow to its relation's cells (``priors.relation_mask``) where any
    are left, except with probability ``priors.RELATION_NOISE``.  ``obj_cat`` and
    ``obj_band`` are written in place.  Returns (cell, the category indices placed)."""
    categories = C.categories(setup)
    placed = []
    for name in names if furniture is None else P.placement_order(names):
        band = C.category_band(name)
        floor = cell == C.CELL_FLOOR
        if band == C.BAND_MID:
            candidates = next_to((cell == C.CELL_FURNITURE) & (obj_cat < 0) & region, floor)
        elif band == C.BAND_HIGH:
            candidates = next_to((cell == C.CELL_WALL) & (obj_cat < 0), floor & region)
            if elsewhere is not None:
                candidates &= ~next_to(candidates, elsewhere)
        else:
            candidates = floor & region if keep_free is None else floor & region & ~keep_free
        if furniture is not None and rng.random() >= P.RELATION_NOISE:
            related = candidates & P.relation_mask(name, band, cell, furniture, obj_cat, categories)
            candidates = related if related.any() else candidates
        for r, c in rng.permutation(np.argwhere(candidates)):
            if band == C.BAND_FLOOR:
                trial = cell.copy()
                trial[r, c] = C.CELL_OBJECT
                if not walkable_connected(trial):
                    continue
                cell = trial
            obj_cat[r, c] = categories.index(name)
            obj_band[r, c] = band
            placed.append(categories.index(name))
            break
    return cell, placed
