"""The scene bank's disk cache (envs.bank_cache): a cached bank equals a fresh build bit for bit,
bad files are rebuilt, the key follows every input, the cache can be turned off; and the
bank's view table equals raycast.cast_view at every pose.

Every test points FORESIT_CACHE_DIR at a temporary folder (never ~/.cache) and calls
``build_bank.__wrapped__`` (the function under the in-memory lru_cache)."""

import shutil
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from envs import bank as B
from envs import bank_cache as BC
from envs import catalog as C
from envs.raycast import DEPTH_RESOLUTION, cast_view

# Small banks: two bathrooms, 2 view columns (about a second to build).
ARGS = ("savn", (401, 402), 20, 2)


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    monkeypatch.setenv(BC.CACHE_DIR_ENV, str(tmp_path))
    monkeypatch.delenv(BC.NO_CACHE_ENV, raising=False)
    return tmp_path / "banks"


@pytest.fixture(scope="module")
def fresh():
    """A build from scratch, no cache involved."""
    return B.compute_bank(*ARGS)


def build(args=ARGS):
    return B.build_bank.__wrapped__(*args)


def assert_bitwise_equal(a: dict, b: dict):
    assert set(a) == set(b)
    for name in a:
        assert a[name].dtype == b[name].dtype and a[name].shape == b[name].shape, name
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def forbid_building(monkeypatch):
    def fail(*args):
        raise AssertionError("built although a valid cache file exists")

    monkeypatch.setattr(B, "compute_bank", fail)


def test_cached_bank_equals_a_fresh_build_bitwise(cache_dir, fresh, monkeypatch):
    path = BC.bank_cache_path(*ARGS)
    assert path.parent == cache_dir and not path.exists()
    first = build()  # builds and writes the file
    assert path.exists()
    assert_bitwise_equal(first, fresh)
    forbid_building(monkeypatch)
    assert_bitwise_equal(build(), fresh)  # read back from the file
    assert sorted(p.name for p in cache_dir.iterdir()) == [path.name]  # no temporary files left


@pytest.mark.parametrize(
    "damage",
    ["garbage", "truncated", "empty", "other_key", "wrong_shape", "missing_array"],
)
def test_a_bad_cache_file_is_rebuilt_not_fatal(cache_dir, fresh, damage):
    path = BC.bank_cache_path(*ARGS)
    build()
    good = path.read_bytes()
    if damage == "garbage":
        path.write_bytes(b"not an npz file" * 10)
    elif damage == "truncated":
        path.write_bytes(good[: len(good) // 2])
    elif damage == "empty":
        path.write_bytes(b"")
    else:
        with np.load(path) as data:
            arrays = {k: data[k] for k in data.files}
        if damage == "other_key":
            arrays["cache_key"] = np.asarray("0" * 64)
        elif damage == "wrong_shape":
            arrays["distance"] = arrays["distance"][:, :1]
        else:
            del arrays["starts"]
        with open(path, "wb") as f:
            np.savez_compressed(f, **arrays)
    with pytest.warns(UserWarning, match="scene-bank cache"):
        arrays = build()
    assert_bitwise_equal(arrays, fresh)
    with np.load(path) as data:  # the file was rewritten whole
        assert str(data["cache_key"]) == BC.bank_cache_key(*ARGS)
        assert_bitwise_equal({k: data[k] for k in data.files if k != "cache_key"}, fresh)


def test_the_key_changes_with_every_input(cache_dir, monkeypatch):
    setup, numbers, grid, width = ARGS
    variants = [
        ARGS,
        ("org", numbers, grid, width),
        (setup, (401, 403), grid, width),
        (setup, (402, 401), grid, width),  # order matters: it is the scene index
        (setup, numbers + (403,), grid, width),
        (setup, numbers, 24, width),
        (setup, numbers, grid, 3),
    ]
    keys = [BC.bank_cache_key(*v) for v in variants]
    paths = [BC.bank_cache_path(*v) for v in variants]
    assert len(set(keys)) == len(keys) and len(set(paths)) == len(paths)
    assert BC.bank_cache_key(*ARGS) == BC.bank_cache_key(setup, list(numbers), np.int64(grid), width)
    monkeypatch.setattr(BC, "_generator_digest", lambda: "another generator")
    assert BC.bank_cache_key(*ARGS) != keys[0]


def test_the_generator_digest_follows_the_source_files(tmp_path, monkeypatch):
    """Editing any of scenes.py, bank.py, raycast.py, catalog.py changes the digest."""
    here = Path(BC.__file__).resolve().parent
    for name in BC._GENERATOR_SOURCES:
        shutil.copy(here / name, tmp_path / name)
    monkeypatch.setattr(BC, "__file__", str(tmp_path / "bank_cache.py"))
    digest = BC._generator_digest.__wrapped__
    base = digest()
    assert base == BC._generator_digest()  # the copies are the real sources
    seen = {base}
    for name in BC._GENERATOR_SOURCES:
        original = (tmp_path / name).read_bytes()
        (tmp_path / name).write_bytes(original + b"\n# edited\n")
        seen.add(digest())
        (tmp_path / name).write_bytes(original)
    assert len(seen) == 1 + len(BC._GENERATOR_SOURCES)
    assert digest() == base


@pytest.mark.parametrize("value", ["1", "true", "yes"])
def test_the_cache_can_be_turned_off(cache_dir, fresh, monkeypatch, value):
    monkeypatch.setenv(BC.NO_CACHE_ENV, value)
    assert BC.bank_cache_dir() is None and BC.bank_cache_path(*ARGS) is None
    assert_bitwise_equal(build(), fresh)
    assert not cache_dir.exists()


def test_default_cache_folder(monkeypatch, tmp_path):
    monkeypatch.delenv(BC.CACHE_DIR_ENV, raising=False)
    monkeypatch.delenv(BC.NO_CACHE_ENV, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert BC.bank_cache_dir() == tmp_path / "foresit_jax" / "banks"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert BC.bank_cache_dir() == Path.home() / ".cache" / "foresit_jax" / "banks"
    monkeypatch.setenv(BC.NO_CACHE_ENV, "0")
    assert BC.bank_cache_dir() is not None


def test_an_unwritable_cache_folder_only_warns(tmp_path, monkeypatch, fresh):
    blocker = tmp_path / "a_file"
    blocker.write_text("the cache folder cannot be made under a file")
    monkeypatch.setenv(BC.CACHE_DIR_ENV, str(blocker))
    monkeypatch.delenv(BC.NO_CACHE_ENV, raising=False)
    with pytest.warns(UserWarning, match="could not write"):
        assert_bitwise_equal(build(), fresh)


def test_make_uses_the_disk_cache(cache_dir, monkeypatch):
    """envs.make goes through the cache (a new size, so that the lru_cache has not seen it)."""
    import envs

    env, params = envs.make("GridNav-v0", split="val", room_types="bathroom", view_width=1)
    path = BC.bank_cache_path("savn", tuple(C.scene_numbers("val", [C.BATHROOM])), 20, 1)
    assert path.exists()
    with np.load(path) as data:
        np.testing.assert_array_equal(data["view_sem"], params.bank.view_sem)
        np.testing.assert_array_equal(data["distance"], params.bank.distance)


@pytest.mark.parametrize("view_width", [2, 3])  # odd: a ray straight along the heading
def test_view_table_equals_cast_view_at_every_pose(view_width):
    """The bank's table casts the rays of a (cell, heading) once for both horizons; it must
    equal raycast.cast_view of each pose, pixel for pixel (every pose, walls included)."""
    layout_numbers = (7, 215)  # a kitchen and a living room
    from envs.scenes import generate_layout

    for number in layout_numbers:
        layout = generate_layout(number, "org", 20)
        grids = [jnp.asarray(g) for g in (layout.cell_type, layout.obj_cat, layout.obj_band)]
        sem, depth_code = map(np.asarray, B._scene_views(layout.cell_type, layout.obj_cat, layout.obj_band, view_width))
        num_poses = 20 * 20 * C.NUM_HEADINGS * C.NUM_HORIZONS
        pos, heading, horizon = B.pose_from_index(jnp.arange(num_poses), 20)
        cast = jax.jit(jax.vmap(lambda p, h, z: cast_view(*grids, p, h, z, view_width)))
        ref_sem, ref_depth = map(np.asarray, cast(pos, heading, horizon))
        np.testing.assert_array_equal(sem, ref_sem.astype(np.int8))
        ref_code = np.clip(np.round(ref_depth * DEPTH_RESOLUTION), 0, 255).astype(np.uint8)
        np.testing.assert_array_equal(depth_code, ref_code)
