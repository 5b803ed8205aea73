"""The scene banks' disk cache (the banks themselves: envs.bank).

A built bank is kept in memory (``build_bank`` is lru-cached) and on disk, as a
compressed ``.npz`` (a few MB) under ``$FORESIT_CACHE_DIR/banks/`` (default
``~/.cache/foresit_jax/banks/``, or ``$XDG_CACHE_HOME/foresit_jax/banks/``).  The file
name carries a hash of everything that determines the arrays (``bank_cache_key``): the
setup, scene numbers, grid size, view width, the room types whose targets are kept, the
source of envs/scenes.py, houses.py, bank.py, dynamics.py, raycast.py and catalog.py, and
the numpy, jax and jaxlib versions and the jax backend that build it.  So editing the
generator or upgrading jax selects a new file; stale files are never read (delete the
folder to reclaim the space).  Files are written atomically (a
temporary file, then ``os.replace``), so concurrent processes are safe; a file that cannot
be read, or whose arrays do not match the expected names, shapes and dtypes, is rebuilt.
``FORESIT_NO_CACHE=1`` turns the disk cache off (neither read nor written); a cache
folder that cannot be written only costs a warning.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import tempfile
import warnings
from pathlib import Path

import jax
import numpy as np

BANK_CACHE_FORMAT = 1  # bump when the file layout (not the arrays) changes
CACHE_DIR_ENV = "FORESIT_CACHE_DIR"  # root of the disk cache; banks go to its "banks" folder
NO_CACHE_ENV = "FORESIT_NO_CACHE"  # "1" (anything but "", "0", "false", "no"): no disk cache
# The modules whose source determines a bank's arrays (hashed into the cache key).
_GENERATOR_SOURCES = (
    "scenes.py",
    "houses.py",
    "priors.py",
    "grid.py",
    "bank.py",
    "dynamics.py",
    "raycast.py",
    "catalog.py",
)


def bank_cache_dir() -> Path | None:
    """The folder of cached banks, or None when the disk cache is off (FORESIT_NO_CACHE)."""
    if os.environ.get(NO_CACHE_ENV, "").strip().lower() not in ("", "0", "false", "no"):
        return None
    root = os.environ.get(CACHE_DIR_ENV)
    if not root:
        root = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "foresit_jax"
    return Path(root).expanduser() / "banks"


@functools.lru_cache(maxsize=1)
def _generator_digest() -> str:
    """sha256 of the source of the modules that generate a bank, and of the library versions."""
    digest = hashlib.sha256()
    here = Path(__file__).resolve().parent
    for name in _GENERATOR_SOURCES:
        digest.update(name.encode() + b"\0" + (here / name).read_bytes() + b"\0")
    import jaxlib

    versions = (np.__version__, jax.__version__, jaxlib.__version__, jax.default_backend())
    digest.update(repr(versions).encode())
    return digest.hexdigest()


def bank_cache_key(
    setup: str, scene_numbers, grid_size: int, view_width: int, target_rooms=(0, 1, 2, 3), priors: bool = False
) -> str:
    """Hex sha256 of every input that determines the arrays of a bank (see the module doc)."""
    inputs = {
        "format": BANK_CACHE_FORMAT,
        "setup": setup,
        "scene_numbers": [int(n) for n in scene_numbers],
        "grid_size": int(grid_size),
        "view_width": int(view_width),
        "target_rooms": [int(r) for r in target_rooms],
        "generator": _generator_digest(),
    }
    if priors:  # only then: the keys of today's layouts stay as they were
        inputs["priors"] = True
    return hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()


def bank_cache_path(
    setup: str, scene_numbers, grid_size: int, view_width: int, target_rooms=(0, 1, 2, 3), priors: bool = False
) -> Path | None:
    """Where the bank of these inputs is (or would be) cached; None when caching is off."""
    folder = bank_cache_dir()
    if folder is None:
        return None
    key = bank_cache_key(setup, scene_numbers, grid_size, view_width, target_rooms, priors)
    kind = "-priors" if priors else ""
    return folder / f"{setup}{kind}-{len(scene_numbers)}scenes-g{grid_size}-w{view_width}-{key[:32]}.npz"


def load(path: Path, key: str, expected: dict) -> dict | None:
    """The arrays of a cache file, or None when it is missing, unreadable or not as expected."""
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            if str(data["cache_key"]) != key or set(data.files) != set(expected) | {"cache_key"}:
                raise ValueError("keys differ")
            arrays = {name: data[name] for name in expected}
        for name, (shape, dtype) in expected.items():
            if arrays[name].shape != shape or arrays[name].dtype != dtype:
                raise ValueError(f"{name}: {arrays[name].shape} {arrays[name].dtype}, expected {shape} {dtype}")
        return arrays
    except Exception as error:  # noqa: BLE001 (a corrupt or foreign file: rebuild, never crash)
        warnings.warn(f"ignoring the unreadable scene-bank cache file {path} ({error!r}); rebuilding it", stacklevel=3)
        return None


def save(path: Path, key: str, arrays: dict) -> None:
    """Write atomically (a temporary file in the same folder, then os.replace)."""
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem + ".", suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            np.savez_compressed(f, cache_key=np.asarray(key), **arrays)
        os.replace(tmp, path)
        tmp = None
    except OSError as error:
        warnings.warn(f"could not write the scene-bank cache file {path} ({error!r})", stacklevel=3)
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass
