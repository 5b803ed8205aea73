"""Static facts of the GridNav world: room types, scene numbers, splits, object categories.

Everything here is plain Python/numpy data; nothing is traced.  Scene numbers follow
AI2-THOR (kitchens 1-30, living rooms 201-230, bedrooms 301-330, bathrooms 401-430) and
the splits follow SAVN (train 1-20, validation the odd layouts 21-29, test the even
layouts 22-30, with the same offsets for every room type).  Houses (``layout="house"``,
envs.houses) are numbered by their number of rooms: 2-room houses 2001-2030, 3-room
houses 3001-3030, 4-room houses 4001-4030, split by ``number % 1000`` the same way.
"""

from __future__ import annotations

import zlib

import numpy as np

CELL_SIZE_M = 0.25

ROOM_TYPES = ("kitchen", "living_room", "bedroom", "bathroom")
KITCHEN, LIVING_ROOM, BEDROOM, BATHROOM = range(4)
ROOM_OFFSETS = (0, 200, 300, 400)

SPLITS = ("train", "val", "test")
LAYOUTS = ("room", "house")  # single AI2-THOR-like rooms, or multi-room houses (envs.houses)
HOUSE_SIZES = (2, 3, 4)  # rooms per house; house numbers are 1000 * rooms + layout
SPLIT_LAYOUTS = {
    "train": tuple(range(1, 21)),
    "val": (21, 23, 25, 27, 29),
    "test": (22, 24, 26, 28, 30),
}

ACTIONS = ("MoveAhead", "RotateLeft", "RotateRight", "LookUp", "LookDown", "Done")
MOVE_AHEAD, ROTATE_LEFT, ROTATE_RIGHT, LOOK_UP, LOOK_DOWN, DONE = range(6)
NUM_ACTIONS = len(ACTIONS)

NUM_HEADINGS = 8  # 45 degree steps, 0 = north (row - 1), clockwise
NUM_HORIZONS = 2  # 0 = level, 1 = 30 degrees down
# (d_row, d_col) of one MoveAhead for each heading.
HEADING_DELTAS = np.array([(-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1)], dtype=np.int32)

# Semantic classes of a view pixel before the object categories.
SEM_NOTHING, SEM_WALL, SEM_FLOOR, SEM_FURNITURE = range(4)
NUM_STRUCTURAL = 4

# Furniture kinds of the layouts with priors (envs.priors; AI2-THOR object types): each is a
# semantic class of its own there, after the categories (``furniture_sem``); today's layouts
# show all furniture as SEM_FURNITURE.
FURNITURE_KINDS = (
    "CounterTop",
    "DiningTable",
    "Shelf",
    "Sofa",
    "ArmChair",
    "CoffeeTable",
    "TVStand",
    "Bed",
    "SideTable",
    "Dresser",
    "Desk",
    "Toilet",
    "Bathtub",
)

# Cell types of the occupancy grid.
CELL_FLOOR, CELL_WALL, CELL_FURNITURE, CELL_OBJECT = range(4)

# Height bands of objects: on the floor, on furniture (mid height), high on walls.
BAND_FLOOR, BAND_MID, BAND_HIGH = range(3)

SAVN_TARGETS = {
    KITCHEN: ("Toaster", "Microwave", "Fridge", "CoffeeMaker", "GarbageCan", "Box", "Bowl"),
    LIVING_ROOM: ("Pillow", "Laptop", "Television", "GarbageCan", "Box", "Bowl"),
    BEDROOM: ("HousePlant", "Lamp", "Book", "AlarmClock"),
    BATHROOM: ("Sink", "ToiletPaper", "SoapBottle", "LightSwitch"),
}

ORG_CATEGORIES = (
    "AlarmClock",
    "Book",
    "Bowl",
    "CellPhone",
    "Chair",
    "CoffeeMachine",
    "DeskLamp",
    "FloorLamp",
    "Fridge",
    "GarbageCan",
    "Kettle",
    "Laptop",
    "LightSwitch",
    "Microwave",
    "Pan",
    "Plate",
    "Pot",
    "RemoteControl",
    "Sink",
    "StoveBurner",
    "Television",
    "Toaster",
)
ORG_TARGETS = {
    KITCHEN: (
        "Bowl",
        "Chair",
        "CoffeeMachine",
        "Fridge",
        "GarbageCan",
        "Kettle",
        "LightSwitch",
        "Microwave",
        "Pan",
        "Plate",
        "Pot",
        "Sink",
        "StoveBurner",
        "Toaster",
    ),
    LIVING_ROOM: (
        "Book",
        "Bowl",
        "Chair",
        "FloorLamp",
        "GarbageCan",
        "Laptop",
        "LightSwitch",
        "RemoteControl",
        "Television",
    ),
    BEDROOM: ("AlarmClock", "Book", "CellPhone", "Chair", "DeskLamp", "GarbageCan", "Laptop", "LightSwitch"),
    BATHROOM: ("GarbageCan", "LightSwitch", "Sink"),
}

# Where each category stands.  Floor objects block movement; mid objects stand on
# furniture; high objects hang on walls.
CATEGORY_BAND = {
    "GarbageCan": BAND_FLOOR,
    "Box": BAND_FLOOR,
    "HousePlant": BAND_FLOOR,
    "FloorLamp": BAND_FLOOR,
    "Chair": BAND_FLOOR,
    "ToiletPaper": BAND_FLOOR,
    "Television": BAND_HIGH,
    "LightSwitch": BAND_HIGH,
    "Microwave": BAND_HIGH,
}  # (everything else: BAND_MID)


def category_band(name: str) -> int:
    return CATEGORY_BAND.get(name, BAND_MID)


def _savn_categories() -> tuple[str, ...]:
    seen: list[str] = []
    for room in range(4):
        for name in SAVN_TARGETS[room]:
            if name not in seen:
                seen.append(name)
    return tuple(seen)


SETUPS = {
    # name: (categories, targets by room, success radius in metres, target encoding)
    "savn": (_savn_categories(), SAVN_TARGETS, 1.0, "word_vector"),
    "org": (ORG_CATEGORIES, ORG_TARGETS, 1.5, "one_hot"),
}
WORD_VECTOR_DIM = 300


def check_setup(setup: str) -> None:
    if setup not in SETUPS:
        raise ValueError(f"unknown setup {setup!r}; choose one of {sorted(SETUPS)}")


def check_split(split: str) -> None:
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; choose one of {list(SPLITS)}")


def check_layout(layout: str) -> None:
    if layout not in LAYOUTS:
        raise ValueError(f"unknown layout {layout!r}; choose one of {list(LAYOUTS)}")


def num_semantic(setup: str, priors: bool = False) -> int:
    """Semantic classes of a view pixel: the structural ones, the setup's categories and,
    under priors, the furniture kinds."""
    return NUM_STRUCTURAL + len(categories(setup)) + (len(FURNITURE_KINDS) if priors else 0)


def furniture_sem(setup: str, kind: int) -> int:
    """The semantic class of furniture kind index ``kind`` (layouts with priors)."""
    return NUM_STRUCTURAL + len(categories(setup)) + int(kind)


def categories(setup: str) -> tuple[str, ...]:
    check_setup(setup)
    return SETUPS[setup][0]


def scene_numbers(split: str, room_types=range(4)) -> list[int]:
    """AI2-THOR scene numbers of a split, room type by room type."""
    check_split(split)
    return [ROOM_OFFSETS[r] + n for r in room_types for n in SPLIT_LAYOUTS[split]]


def house_numbers(split: str, sizes=HOUSE_SIZES) -> list[int]:
    """House numbers of a split, house size by house size."""
    check_split(split)
    return [1000 * size + n for size in sizes for n in SPLIT_LAYOUTS[split]]


def is_house(scene_number: int) -> bool:
    return int(scene_number) >= 1000


def house_size_of(number: int) -> int:
    """The number of rooms of house ``number`` (2001-2030: 2, ... 4001-4030: 4)."""
    size, layout = divmod(int(number), 1000)
    if size not in HOUSE_SIZES or not 1 <= layout <= 30:
        raise ValueError(
            f"{number} is not a house number (2-room houses 2001-2030, 3-room 3001-3030, 4-room 4001-4030)"
        )
    return size


def room_type_of(scene_number: int) -> int:
    room, layout = divmod(scene_number, 100)
    room = {0: KITCHEN, 2: LIVING_ROOM, 3: BEDROOM, 4: BATHROOM}.get(room)
    if room is None or not 1 <= layout <= 30:
        raise ValueError(
            f"scene number {scene_number} is not an AI2-THOR layout "
            "(kitchens 1-30, living rooms 201-230, bedrooms 301-330, bathrooms 401-430)"
        )
    return room


def word_vector(name: str) -> np.ndarray:
    """A fixed 300-d stand-in for the GloVe vector of a category name (seeded by the name)."""
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    return (0.3 * rng.standard_normal(WORD_VECTOR_DIM)).astype(np.float32)


def target_encodings(setup: str) -> np.ndarray:
    """[n_categories, D]: the target input the agent sees for each category."""
    cats, _, _, kind = SETUPS[setup]
    if kind == "one_hot":
        return np.eye(len(cats), dtype=np.float32)
    return np.stack([word_vector(c) for c in cats])
