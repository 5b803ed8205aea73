"""Procedural multi-room houses (``layout="house"``): 2-4 rooms of the single rooms' types
joined by doorways (numpy, host side; deterministic in the house number).

A house is a rectangle of floor cut by one-cell walls into rooms: a binary space partition
whose every cut splits the house's rooms into two groups, across the longer side of the
part it cuts, in proportion to the rooms' areas.  Each cut gets one doorway
(``DOOR_WIDTH`` cells) between two rooms on either side of it that share at least that
much of the wall, so the rooms form a tree and every path between two rooms goes through
doorways.  The ray-cast view sees through a doorway (its cells are floor) and never
through a wall.

The rooms of a house have distinct types (drawn from the four), each about
``HOUSE_ROOM_SCALE`` of the area of a single room of its type, and are furnished as a
single room of that type is (``scenes.furnish``).  Each target category of the setup that
belongs to one of the house's room types stands once in the house, in a room of a type it
belongs to: a category two room types share (GarbageCan in kitchens and living rooms)
stands in whichever of them comes first in the house's (random) room order.  An object
high on a wall hangs on a wall that faces its own room's floor and no other room's, so it
is seen from its room only.  So every target has one instance in one room, and
``Layout.target_room`` says which.
"""

from __future__ import annotations

import numpy as np

from envs import catalog as C
from envs import priors as P
from envs.grid import next_to, walkable_connected
from envs.scenes import ROOM_SIZE_RANGES, Layout, _rng, furnish, place_objects

HOUSE_GRID_SIZE = 30  # the largest footprint (28 x 28 cells, 7 m) plus its outer walls
DOOR_WIDTH = 3  # cells (0.75 m), as the single living rooms' doorway
MIN_SIDE = 4  # a room's shortest interior side, in cells
HOUSE_ROOM_SCALE = (0.7, 1.0)  # a house room's area over a single room's of its type (uniform)


def nominal_area(room: int) -> float:
    """The mean interior area (cells) of a single room of type ``room``."""
    (r_lo, r_hi), (c_lo, c_hi) = ROOM_SIZE_RANGES[room]
    return (r_lo + r_hi) / 2 * (c_lo + c_hi) / 2


def house_room_types(number: int) -> tuple[int, ...]:
    """The room types of house ``number``, in its room order (cheap: no layout is built)."""
    size = C.house_size_of(number)
    return tuple(int(t) for t in _rng("house", number).permutation(4)[:size])


def generate_house(number: int, setup: str, grid_size: int = HOUSE_GRID_SIZE, priors: bool = False) -> Layout:
    """House ``number`` (2001-2030, 3001-3030, 4001-4030) under ``setup``'s categories; with
    ``priors``, its rooms in adjacent pairs, furnished with kinds and filled by relations
    (envs.priors)."""
    C.check_setup(setup)
    if grid_size < HOUSE_GRID_SIZE:
        raise ValueError(f"a house needs grid_size >= {HOUSE_GRID_SIZE}, got {grid_size}")
    types = house_room_types(number)
    rng = _rng("house", number)
    rng.permutation(4)  # the draw house_room_types made
    first_k = None
    if priors:
        rng = _rng("priors-house", number)
        types, first_k = P.room_order(types, rng)
    areas = [nominal_area(t) * rng.uniform(*HOUSE_ROOM_SCALE) for t in types]
    aspect = rng.uniform(0.75, 1.0 / 0.75)
    inner = grid_size - 2
    rows = int(np.clip(round(np.sqrt(sum(areas) * aspect)) + 1, 2 * MIN_SIDE + 1, inner))
    cols = int(np.clip(round(sum(areas) / rows) + 1, 2 * MIN_SIDE + 1, inner))
    top, left = int(rng.integers(1, grid_size - rows)), int(rng.integers(1, grid_size - cols))
    rooms, doors = _partition((top, left, rows, cols), list(enumerate(areas)), rng, first_k)

    cell = np.full((grid_size, grid_size), C.CELL_WALL, np.int8)
    cell_room = np.full((grid_size, grid_size), -1, np.int8)
    for (r, c, h, w), index in rooms:
        cell[r : r + h, c : c + w] = C.CELL_FLOOR
        cell_room[r : r + h, c : c + w] = index
    is_door = np.zeros(cell.shape, bool)
    is_door[tuple(np.array(doors).T)] = True
    # The cells in front of a doorway stay free (no furniture, no floor object): then a room
    # whose own floor is connected stays so without its doorways, and no doorway is blocked.
    keep_free = next_to(cell == C.CELL_FLOOR, is_door)
    rects = {index: rect for rect, index in rooms}
    furniture = np.full(cell.shape, -1, np.int8) if priors else None
    for index, room in enumerate(types):  # each room furnished on its own (its floor kept connected)
        r0, c0, h, w = rects[index]
        alone = np.full(cell.shape, C.CELL_WALL, np.int8)
        alone[r0 : r0 + h, c0 : c0 + w] = cell[r0 : r0 + h, c0 : c0 + w]
        if priors:
            alone, kinds = P.furnish_with_kinds(alone, furniture, room, rng, rects[index], keep_free)
            furniture[r0 : r0 + h, c0 : c0 + w] = kinds[r0 : r0 + h, c0 : c0 + w]
        else:
            alone = furnish(alone, room, rng, rects[index], keep_free)
        cell[r0 : r0 + h, c0 : c0 + w] = alone[r0 : r0 + h, c0 : c0 + w]
    cell[is_door] = C.CELL_FLOOR

    obj_cat = np.full(cell.shape, -1, np.int8)
    obj_band = np.full(cell.shape, -1, np.int8)
    rng = _rng("priors-house-objects" if priors else "house-objects", setup, number)
    categories, target_room = C.categories(setup), {}
    for index, room in enumerate(types):
        names = [n for n in C.SETUPS[setup][1][room] if categories.index(n) not in target_room]
        elsewhere = (cell_room >= 0) & (cell_room != index)
        cell, placed = place_objects(
            cell, obj_cat, obj_band, setup, names, rng, cell_room == index, elsewhere, keep_free, furniture
        )
        target_room.update(dict.fromkeys(placed, index))
    if not walkable_connected(cell):
        raise AssertionError(f"house {number}: the floor is not connected")
    return Layout(number, -1, cell, obj_cat, obj_band, cell_room, types, target_room, furniture)


def _partition(rect, rooms, rng, first_k=None):
    """([(rect, room index)], door cells [(row, col)]) of ``rect`` = (top, left, rows, cols)
    cut between ``rooms`` = [(room index, area)] (see the module doc); ``first_k``, when
    given, is the first cut's count of rooms on its first side."""
    if len(rooms) == 1:
        return [(rect, rooms[0][0])], []
    k = len(rooms) // 2 + int(len(rooms) % 2 and rng.random() < 0.5)  # 1|1, 1|2 or 2|1, 2|2
    k = k if first_k is None else first_k
    first, second = rooms[:k], rooms[k:]
    share = sum(a for _, a in first) / sum(a for _, a in rooms)
    top, left, rows, cols = rect
    across_cols = cols >= rows  # the wall is a column: it cuts across the columns
    span = cols if across_cols else rows
    if span < 2 * MIN_SIDE + 1:
        raise AssertionError(f"a {rows} x {cols} part cannot hold rooms {rooms}")
    cut = int(np.clip(round(share * (span - 1)), MIN_SIDE, span - 1 - MIN_SIDE))  # first part's width
    if across_cols:
        part_a, part_b = (top, left, rows, cut), (top, left + cut + 1, rows, cols - cut - 1)
    else:
        part_a, part_b = (top, left, cut, cols), (top + cut + 1, left, rows - cut - 1, cols)
    rooms_a, doors_a = _partition(part_a, first, rng)
    rooms_b, doors_b = _partition(part_b, second, rng)
    wall = left + cut if across_cols else top + cut

    def along(r):  # the interval a room covers along the wall, if it touches the wall
        (t, l, h, w), _ = r
        touches = (l + w == wall or l == wall + 1) if across_cols else (t + h == wall or t == wall + 1)
        return (t, t + h) if across_cols else (l, l + w), touches

    pairs = []
    for ra in rooms_a:
        for rb in rooms_b:
            (a0, a1), ta = along(ra)
            (b0, b1), tb = along(rb)
            lo, hi = max(a0, b0), min(a1, b1)
            if ta and tb and hi - lo >= DOOR_WIDTH:
                pairs.append((lo, hi))
    if not pairs:
        raise AssertionError(f"no two rooms across the wall at {wall} share {DOOR_WIDTH} cells")
    lo, hi = pairs[int(rng.integers(len(pairs)))]
    start = int(rng.integers(lo, hi - DOOR_WIDTH + 1))
    door = [(start + i, wall) if across_cols else (wall, start + i) for i in range(DOOR_WIDTH)]
    return rooms_a + rooms_b, doors_a + doors_b + door
