"""Layouts with the regularities of real homes (``GridNav(priors=True)``; numpy, host side).

Today's layouts (envs.scenes, envs.houses) furnish a room with pieces of one semantic class
at random places and stand every target on a uniformly random cell of its height band, so
a first view says nothing about where an unseen target is (docs/foresight.md measures
it).  Under priors:

* **Furniture of distinct kinds** (``FURNITURE_KINDS``, AI2-THOR object types), each its own
  semantic class in the view (``catalog.furniture_sem``), a handful per room type
  (``PRIOR_FURNITURE``), some placed near another kind (the coffee table by the sofa, the
  side tables by the bed, the second counter by the first).
* **Every target category placed by a relation** (``RELATIONS``): a mid-band object stands
  on furniture of the given kinds, a floor object beside them, a high object on a wall
  within ``NEAR_CELLS`` of them; ``near`` prefers cells within ``NEAR_CELLS`` of categories placed
  before (the toaster by the coffee maker, the pans by the stove); ``zone="corner"`` puts
  an object in a corner of its room.  With probability ``RELATION_NOISE`` an object is
  placed as today's layouts place it (uniformly over its band), and where a room has no
  cell that satisfies the relation it falls back to that too.
* **Houses** (envs.houses with priors): each room furnished and filled as above, and room
  types in adjacent pairs, kitchen beside living room and bedroom beside bathroom
  (``ROOM_PAIRS``), joined by a doorway, except with probability ``RELATION_NOISE``.
* **Target encodings with meaning** (savn): ``prior_word_vector`` mixes a category's own
  random vector with vectors of its anchor furniture kinds and ``near`` categories, so
  categories that share anchors get related vectors (cosine about 0.5).

Sources: the ``on`` kinds of mid-band objects are a subset of each object type's "default
compatible receptacles" in AI2-THOR's Object Types documentation
(ai2thor.allenai.org/ithor/documentation/objects/object-types), the ones its kitchens,
living rooms, bedrooms and bathrooms use most; the floor and wall relations, ``near`` and
the zones are ours, written from how AI2-THOR's artist-made scenes look (the television
above its stand facing the sofa, the toilet paper by the toilet, the garbage can by the
counter).  Every choice is here, in one table, to be read and changed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from envs import catalog as C
from envs.grid import next_to, walkable_connected, within

RELATION_NOISE = 0.1  # share of objects (and of houses' room orders) placed as today's layouts place them
NEAR_CELLS = 2  # "near": within this Chebyshev distance, in cells (0.5 m)
FURNITURE_KINDS = C.FURNITURE_KINDS


@dataclass(frozen=True)
class Piece:
    """A piece of furniture: its kind, footprint (rows x cols, either orientation), whether
    it stands with a whole side against a wall (its long side, or with ``head`` its short
    side, as a bed's head), the kind it stands near (within NEAR_CELLS) and the kind it
    faces from across the room, if any."""

    kind: str
    rows: int
    cols: int
    against_wall: bool
    near: str | None = None
    opposite: str | None = None
    head: bool = False


# A room's grammar: the first piece anywhere against a wall, the others near it or across
# the room from it (the counters in an L, the dining table across; the TV stand facing the
# sofa, the coffee table before it; the dresser facing the bed, side tables beside it).
PRIOR_FURNITURE = {
    C.KITCHEN: (
        Piece("CounterTop", 1, 5, True),
        Piece("CounterTop", 1, 4, True, near="CounterTop"),
        Piece("DiningTable", 2, 3, False, opposite="CounterTop"),
        Piece("Shelf", 1, 4, True, near="DiningTable"),
        Piece("Shelf", 1, 3, True, near="DiningTable"),
    ),
    C.LIVING_ROOM: (
        Piece("Sofa", 1, 4, True),
        Piece("TVStand", 1, 3, True, opposite="Sofa"),
        Piece("CoffeeTable", 2, 2, False, near="Sofa"),
        Piece("ArmChair", 1, 1, False, near="CoffeeTable"),
        Piece("SideTable", 1, 1, False, near="Sofa"),
        Piece("Shelf", 1, 2, True, near="TVStand"),
        Piece("DiningTable", 2, 3, False),
    ),
    C.BEDROOM: (
        Piece("Bed", 3, 2, True, head=True),
        Piece("SideTable", 1, 1, True, near="Bed"),
        Piece("Dresser", 1, 3, True, opposite="Bed"),
        Piece("Desk", 1, 2, True, near="Dresser"),
        Piece("SideTable", 1, 1, False, near="Bed"),
    ),
    C.BATHROOM: (
        Piece("Bathtub", 1, 3, True),
        Piece("CounterTop", 1, 2, True, opposite="Bathtub"),
        Piece("Toilet", 1, 1, True, near="CounterTop"),
    ),
}


@dataclass(frozen=True)
class Relation:
    """Where a category stands: on (mid band), beside (floor band) or on the wall next to
    (high band) furniture of the kinds ``on``; near categories placed before it; in a
    ``zone`` ("corner") of its room."""

    on: tuple[str, ...] = ()
    near: tuple[str, ...] = ()
    zone: str | None = None


RELATIONS = {
    # On furniture (mid band): a subset of AI2-THOR's default compatible receptacles.
    "Toaster": Relation(on=("CounterTop",), near=("CoffeeMaker", "CoffeeMachine")),
    "CoffeeMaker": Relation(on=("CounterTop",), near=("Toaster",)),
    "CoffeeMachine": Relation(on=("CounterTop",), near=("Toaster",)),
    "Fridge": Relation(on=("CounterTop",)),  # GridNav's fridge stands at a counter (mid band)
    "StoveBurner": Relation(on=("CounterTop",)),
    "Pan": Relation(on=("CounterTop",), near=("StoveBurner",)),
    "Pot": Relation(on=("CounterTop",), near=("StoveBurner",)),
    "Kettle": Relation(on=("CounterTop",), near=("StoveBurner",)),
    "Sink": Relation(on=("CounterTop",)),
    "SoapBottle": Relation(on=("CounterTop", "Bathtub"), near=("Sink",)),
    "Bowl": Relation(on=("DiningTable", "CoffeeTable")),
    "Plate": Relation(on=("DiningTable",), near=("Bowl",)),
    "Pillow": Relation(on=("Sofa", "ArmChair", "Bed")),
    "Laptop": Relation(on=("Desk", "CoffeeTable")),
    "RemoteControl": Relation(on=("CoffeeTable", "Sofa")),
    "Book": Relation(on=("Shelf", "SideTable")),
    "CellPhone": Relation(on=("SideTable", "Bed")),
    "AlarmClock": Relation(on=("SideTable",)),
    "Lamp": Relation(on=("SideTable", "Dresser")),
    "DeskLamp": Relation(on=("Desk",)),
    # High on a wall, next to furniture or in a corner.
    "Television": Relation(on=("TVStand",)),
    "Microwave": Relation(on=("CounterTop",)),
    "LightSwitch": Relation(zone="corner"),
    # On the floor, beside furniture or in a corner.
    "GarbageCan": Relation(on=("CounterTop", "Desk", "SideTable")),
    "Box": Relation(on=("Shelf",)),
    "HousePlant": Relation(zone="corner"),
    "FloorLamp": Relation(on=("Sofa", "ArmChair")),
    "Chair": Relation(on=("DiningTable", "Desk")),
    "ToiletPaper": Relation(on=("Toilet",)),
}

# Houses: room types that stand side by side, joined by a doorway.
ROOM_PAIRS = ((C.KITCHEN, C.LIVING_ROOM), (C.BEDROOM, C.BATHROOM))


def placement_order(names) -> list[str]:
    """``names`` with the most constrained first (the fewest anchor kinds; a zone counts as
    none), keeping the given order among equals: so the alarm clock, which stands on side
    tables only, finds one free before the lamp and the book, which have other places."""
    return sorted(names, key=lambda n: len(RELATIONS[n].on) or 99)


def kind_index(kind: str) -> int:
    return FURNITURE_KINDS.index(kind)


def furnish_with_kinds(cell, furniture, room: int, rng: np.random.Generator, rect, keep_free=None):
    """(cell, furniture) with room type ``room``'s ``PRIOR_FURNITURE`` placed inside ``rect`` =
    (top, left, rows, cols): each piece at a random orientation and place among those that
    keep the floor connected, avoid ``keep_free`` and, for a piece against a wall, lay a
    whole side on one (``_side_on_wall``); a piece with ``near`` goes within NEAR_CELLS of
    that kind where it can, one with ``opposite`` among the quarter of its places farthest
    across the room's centre from that kind.  ``furniture`` (int8 [G, G], -1 where none)
    gets each piece's kind index.  A piece with no valid place is left out."""
    top, left, rows, cols = rect
    cell, furniture = cell.copy(), furniture.copy()
    for piece in PRIOR_FURNITURE[room]:
        places = []
        for h, w in {(piece.rows, piece.cols), (piece.cols, piece.rows)}:
            for r in range(top, top + rows - h + 1):
                for c in range(left, left + cols - w + 1):
                    if (cell[r : r + h, c : c + w] != C.CELL_FLOOR).any():
                        continue
                    if keep_free is not None and keep_free[r : r + h, c : c + w].any():
                        continue
                    if piece.against_wall and not _side_on_wall(cell, r, c, h, w, piece.head):
                        continue
                    places.append((r, c, h, w))
        if not places:
            continue
        order = rng.permutation(len(places))
        if piece.opposite is not None and (furniture == kind_index(piece.opposite)).any():
            centre = np.array([top + (rows - 1) / 2, left + (cols - 1) / 2])
            away = np.argwhere(furniture == kind_index(piece.opposite)).mean(0) - centre
            across = np.array([(np.array([r + (h - 1) / 2, c + (w - 1) / 2]) - centre) @ away for r, c, h, w in places])
            best = across[order] <= np.quantile(across, 0.25)
            order = np.concatenate([order[best], order[~best]])
        if piece.near is not None:
            anchor = within(furniture == kind_index(piece.near), NEAR_CELLS)
            near = np.array([anchor[r : r + h, c : c + w].any() for r, c, h, w in places])
            order = np.concatenate([order[near[order]], order[~near[order]]])  # near places first
        for i in order:
            r, c, h, w = places[i]
            trial = cell.copy()
            trial[r : r + h, c : c + w] = C.CELL_FURNITURE
            if walkable_connected(trial):
                cell = trial
                furniture[r : r + h, c : c + w] = kind_index(piece.kind)
                break
    return cell, furniture


def _side_on_wall(cell, r, c, h, w, head: bool) -> bool:
    """Whether a whole side of the h x w block at (r, c) lies against wall cells: a long
    side (a short one with ``head``; any side of a square)."""
    wall = cell == C.CELL_WALL
    sides = {
        "top": wall[r - 1, c : c + w].all(),
        "bottom": wall[r + h, c : c + w].all(),
        "left": wall[r : r + h, c - 1].all(),
        "right": wall[r : r + h, c + w].all(),
    }
    if h == w:
        return any(sides.values())
    across_rows = (w > h) != head  # the wanted side runs along a row (top or bottom)
    return sides["top"] or sides["bottom"] if across_rows else sides["left"] or sides["right"]


def _corners(cell: np.ndarray) -> np.ndarray:
    """Floor-or-object cells with walls on two perpendicular sides (a room's corners)."""
    wall = cell == C.CELL_WALL
    n, s, w, e = (np.zeros_like(wall) for _ in range(4))
    n[1:, :], s[:-1, :], w[:, 1:], e[:, :-1] = wall[:-1, :], wall[1:, :], wall[:, :-1], wall[:, 1:]
    return (cell != C.CELL_WALL) & (cell != C.CELL_FURNITURE) & ((n | s) & (w | e))


def relation_mask(name: str, band: int, cell, furniture, obj_cat, categories) -> np.ndarray:
    """bool [G, G]: the cells where category ``name`` (of height band ``band``) would stand
    by its relation (before the band's own conditions: free, next to floor, the region)."""
    rel = RELATIONS[name]
    if rel.zone == "corner":
        corner = _corners(cell)
        anchor = corner if band == C.BAND_FLOOR else within(corner, 1)
    else:
        kinds = np.isin(furniture, [kind_index(k) for k in rel.on])
        if band == C.BAND_MID:  # on the furniture
            anchor = kinds
        elif band == C.BAND_FLOOR:  # beside it
            anchor = next_to(np.ones_like(kinds), kinds)
        else:  # on the wall within NEAR_CELLS of it (the wall right behind it faces no floor)
            anchor = within(kinds, NEAR_CELLS)
    placed = [categories.index(n) for n in rel.near if n in categories and (obj_cat == categories.index(n)).any()]
    if placed:
        close = within(np.isin(obj_cat, placed), NEAR_CELLS)
        if (anchor & close).any():
            anchor = anchor & close
    return anchor


def room_order(types: tuple[int, ...], rng: np.random.Generator) -> tuple[tuple[int, ...], int]:
    """(room types in house order, the first part's room count) such that each of
    ``ROOM_PAIRS`` present in ``types`` stays in one part of the first cut (so its two rooms
    share a wall with a doorway in it); with probability RELATION_NOISE, ``types`` as drawn
    and a random cut, as today's houses."""
    size = len(types)
    default_k = size // 2 + int(size % 2 and rng.random() < 0.5)
    if rng.random() < RELATION_NOISE or size == 1:
        return tuple(types), default_k
    pairs = [p for p in ROOM_PAIRS if set(p) <= set(types)]
    singles = [t for t in types if not any(t in p for p in pairs)]
    groups = [list(p) if rng.random() < 0.5 else list(p[::-1]) for p in pairs] + [[t] for t in singles]
    groups = [groups[i] for i in rng.permutation(len(groups))]
    order = tuple(t for g in groups for t in g)
    return order, len(groups[0]) if len(groups) > 1 else default_k


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def prior_word_vector(name: str) -> np.ndarray:
    """A 300-d stand-in for a word vector that carries the priors: the unit mix of the
    category's own random vector (``catalog.word_vector``), the mean vector of its anchor
    furniture kinds (or of its zone) and, at half weight, the own vectors of its ``near``
    categories, scaled to ``word_vector``'s norm.  Categories that share anchors get
    related vectors, as real word vectors relate "toaster" and "counter"."""
    rel = RELATIONS[name]
    anchors = [C.word_vector("furniture:" + k) for k in rel.on] or [C.word_vector("zone:" + str(rel.zone))]
    parts = [_unit(C.word_vector(name)), _unit(np.mean(anchors, 0))]
    if rel.near:
        parts.append(0.5 * _unit(np.mean([C.word_vector(n) for n in rel.near], 0)))
    return (_unit(np.sum(parts, 0)) * np.linalg.norm(C.word_vector(name))).astype(np.float32)


def target_encodings(setup: str) -> np.ndarray:
    """[n_categories, D]: the target input under priors: ``prior_word_vector`` where the
    setup gives word vectors (savn), else as ``catalog.target_encodings`` (org's one-hot)."""
    if C.SETUPS[setup][3] == "word_vector":
        return np.stack([prior_word_vector(c) for c in C.categories(setup)])
    return C.target_encodings(setup)
