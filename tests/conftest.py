"""Shared, session-scoped environment fixtures.

Scene banks are expensive (ray casting every pose of every scene and the BFS oracle), so
each split is built once per test session; ``envs.bank.build_bank`` is lru-cached too, so
``envs.make`` with the same arguments elsewhere reuses the arrays.  Banks of the train
split use ``view_width=2`` (the view width only sets the number of rays; the dynamics,
time limits and oracle are the same), which keeps them cheap.
"""

import os
import shutil
import tempfile

import jax
import pytest

import envs

_CACHE = "JAX_COMPILATION_CACHE_DIR"


def pytest_configure(config):
    """One persistent XLA compilation cache for the whole test session, shared by the
    xdist workers (which inherit this environment variable from the controller) and the
    subprocesses the tests start.  The same program is compiled many times in a session:
    `jax.clear_caches()` after every module (below) drops compiled programs that later
    modules compile again, and workers compile what the other worker did; each is
    compiled once here, then loaded.  A fresh, empty folder per session (deleted at its
    end): nothing is reused from an earlier run, so the suite still compiles what it tests.
    A user's own `JAX_COMPILATION_CACHE_DIR` is left as it is."""
    if not hasattr(config, "workerinput") and _CACHE not in os.environ:
        os.environ[_CACHE] = config._foresit_xla_cache = tempfile.mkdtemp(prefix="foresit-xla-cache-")
    # jax is imported already (it read its environment then): tell it directly.
    jax.config.update("jax_compilation_cache_dir", os.environ.get(_CACHE))


@pytest.fixture(scope="module")
def cheap_experiments():
    """In-process calls of the experiments CLIs made cheap for a test module
    (`train_helpers.patch_for_experiments`); a module asks for it with
    `pytestmark = pytest.mark.usefixtures("cheap_experiments")`."""
    import train_helpers

    with pytest.MonkeyPatch.context() as mp:
        train_helpers.patch_for_experiments(mp)
        yield


# Module-scoped fixtures that train (tens of seconds each): the tests that use one are
# sent to one xdist worker together (`--dist loadgroup` in pyproject.toml), so it is built
# once, not once on each worker.
SHARED_TRAINING_FIXTURES = ("finished_run", "tiny_sweep", "ppo_run")


# tryfirst: xdist's worker reads the marks in its own pytest_collection_modifyitems, which
# would otherwise run before this one and see none.
@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    for item in items:
        for name in SHARED_TRAINING_FIXTURES:
            if name in getattr(item, "fixturenames", ()):
                item.add_marker(pytest.mark.xdist_group(name))


def pytest_unconfigure(config):
    folder = getattr(config, "_foresit_xla_cache", None)
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)
        del os.environ[_CACHE]


@pytest.fixture(scope="session")
def savn_test():
    """(env, params) of the savn setup, test split (layouts 22..30, all room types)."""
    return envs.make("GridNav-v0", setup="savn", split="test")


@pytest.fixture(scope="session")
def org_test():
    """(env, params) of the org setup, test split."""
    return envs.make("GridNav-v0", setup="org", split="test")


@pytest.fixture(scope="session")
def savn_train_narrow():
    """(env, params) of the savn setup, train split, 2 view columns (cheap to build)."""
    return envs.make("GridNav-v0", setup="savn", split="train", view_width=2)


@pytest.fixture(scope="session")
def savn_val_narrow():
    """(env, params) of the savn setup, validation split (living rooms and bathrooms), 2 view columns."""
    return envs.make("GridNav-v0", setup="savn", split="val", room_types=["living_room", "bathroom"], view_width=2)


@pytest.fixture(scope="session")
def savn_kit(savn_test):
    """env_helpers.Kit of the savn test split: numpy bank and once-compiled jitted functions."""
    from env_helpers import Kit

    return Kit(*savn_test)


@pytest.fixture(scope="session")
def org_kit(org_test):
    from env_helpers import Kit

    return Kit(*org_test)


@pytest.fixture(scope="module", autouse=True)
def _free_compiled_programs():
    """Drop every jit cache after each test module. One process compiles hundreds of XLA
    programs; with all of them kept alive for the whole session (cached Trainers and
    Evaluators), the suite segfaulted inside XLA's compiler near its end, twice at the same
    test, which passes alone."""
    yield
    import jax

    jax.clear_caches()
