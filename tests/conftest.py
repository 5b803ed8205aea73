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
from pathlib import Path

import jax
import pytest

import envs
from envs import bank_cache

_CACHE = "JAX_COMPILATION_CACHE_DIR"

# The two tiers (docs/testing.md).  `python -m pytest` runs the default tier: every test not
# marked `slow`.  `python -m pytest -m slow` runs the slow tier: what trains for real, runs a
# CLI end to end, or compiles a whole method matrix.  A test named by its node id runs
# whatever its tier; `-m "slow or not slow"` runs both.
SLOW = "slow"
# A default-tier test should take at most this long (setup and call, on the 2-core CPU the
# suite is measured on); longer ones are listed at the end of the run.
DEFAULT_TIER_BUDGET_S = 5.0


def xla_cache_dir() -> Path | None:
    """The tests' persistent XLA compilation cache: `xla-tests` beside the scene-bank cache
    (`$FORESIT_CACHE_DIR`, default `~/.cache/foresit_jax`); None when the disk cache is off
    (FORESIT_NO_CACHE=1).  Safe to delete at any time."""
    banks = bank_cache.bank_cache_dir()
    return None if banks is None else banks.parent / "xla-tests"


def pytest_configure(config):
    """One persistent XLA compilation cache, shared by the xdist workers (which inherit this
    environment variable from the controller), the subprocesses the tests start and later
    sessions.  `jax.clear_caches()` after every module (below) drops compiled programs that
    later modules compile again, and workers compile what the other worker did: each is
    compiled once, then loaded.  jax keys an entry by the program, the jax and jaxlib
    versions, the backend and the compile options, so one folder serves every stack.  It
    lives in the user's cache folder (`xla_cache_dir`), where a second run of the suite
    finds it; with FORESIT_NO_CACHE=1, a fresh folder per session, deleted at its end.  A
    user's own `JAX_COMPILATION_CACHE_DIR` is left as it is."""
    config.addinivalue_line(
        "markers",
        f"{SLOW}: trains, runs a CLI end to end or compiles many programs "
        "(the slow tier: python -m pytest -m slow; docs/testing.md)",
    )
    config.addinivalue_line(
        "markers",
        "readme_snippet: the README's library snippet at its own sizes (.ci/run runs "
        "it again on the unconstrained resolution of Python 3.11)",
    )
    if not hasattr(config, "workerinput") and _CACHE not in os.environ:
        folder = xla_cache_dir()
        if folder is None:
            folder = config._foresit_xla_cache = Path(tempfile.mkdtemp(prefix="foresit-xla-cache-"))
        folder.mkdir(parents=True, exist_ok=True)
        os.environ[_CACHE] = str(folder)
    # jax is imported already (it read its environment then): tell it directly.
    jax.config.update("jax_compilation_cache_dir", os.environ.get(_CACHE))
    # Every program goes to the cache, not only those that took a second to compile (jax's
    # default): after `jax.clear_caches()` and on the other worker, the many small programs
    # the tests compile are loaded, not compiled again (the default tier cold: 583 s of test
    # time summed over both workers before, 514 s after; docs/testing.md).
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)


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
# once, not once on each worker.  A test that uses one belongs to the slow tier, and must
# say so (`@pytest.mark.slow`): the collection stops with the list of those that do not.
SHARED_TRAINING_FIXTURES = ("finished_run", "tiny_sweep", "ppo_run", "run6")


def _names_tests(config) -> bool:
    """Whether the command line names tests by node id (`file.py::test`)."""
    return any("::" in str(arg) for arg in config.args)


# The default tier's modules are xdist groups, one module to one worker: a module-scoped
# fixture (a scene bank, a trained state, a compiled program) is then built once, not once
# on each worker, which cut the default tier's setup time from 105 s to 73 s summed (cold,
# docs/testing.md).  The slow tier's tests are spread one by one (its modules are long),
# except those that share a training fixture, which run together on one worker.
# tryfirst: xdist's worker reads the marks in its own pytest_collection_modifyitems, which
# would otherwise run before this one and see none.
@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    unmarked = []
    for item in items:
        group = None
        for name in SHARED_TRAINING_FIXTURES:
            if name in getattr(item, "fixturenames", ()):
                group = name
                if item.get_closest_marker(SLOW) is None:
                    unmarked.append(f"{item.nodeid} (uses {name})")
        if group is None and item.get_closest_marker(SLOW) is None:
            group = item.nodeid.split("::")[0]  # a default-tier module runs on one worker (below)
        if group is not None:
            item.add_marker(pytest.mark.xdist_group(group))
    if unmarked:
        raise pytest.UsageError(
            "tests that use a training fixture must be marked @pytest.mark.slow (docs/testing.md): "
            + ", ".join(unmarked)
        )
    if config.option.markexpr or _names_tests(config):
        return  # the user chose (-m slow, -m "slow or not slow", a node id)
    slow = [item for item in items if item.get_closest_marker(SLOW) is not None]
    if slow:
        config.hook.pytest_deselected(items=slow)
        items[:] = [item for item in items if item.get_closest_marker(SLOW) is None]


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """After a run: the default-tier tests over the budget (a hint, never a failure), and
    how to run the slow tier when it was left out."""
    seconds = {}
    for reports in terminalreporter.stats.values():
        for report in reports:
            if getattr(report, "when", None) in ("setup", "call") and SLOW not in getattr(report, "keywords", {}):
                seconds[report.nodeid] = seconds.get(report.nodeid, 0.0) + report.duration
    over = sorted(((s, n) for n, s in seconds.items() if s > DEFAULT_TIER_BUDGET_S), reverse=True)
    if over:
        terminalreporter.write_sep(
            "-",
            f"default-tier tests over the {DEFAULT_TIER_BUDGET_S:g} s budget "
            "(make them cheaper or mark them slow: docs/testing.md)",
        )
        for s, nodeid in over:
            terminalreporter.write_line(f"{s:6.1f}s {nodeid}")
    if not config.option.markexpr and not _names_tests(config):  # the default tier ran, not the slow one
        terminalreporter.write_line("the slow tier was left out: python -m pytest -m slow runs it")


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
def priors_test():
    """(env, params) of the savn setup with priors (envs.priors), test split."""
    return envs.make("GridNav-v0", setup="savn", split="test", priors=True)


@pytest.fixture(scope="session")
def priors_kit(priors_test):
    from env_helpers import Kit

    return Kit(*priors_test)


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
