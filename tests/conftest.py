"""Shared, session-scoped environment fixtures.

Scene banks are expensive (ray casting every pose of every scene and the BFS oracle), so
each split is built once per test session; ``envs.bank.build_bank`` is lru-cached too, so
``envs.make`` with the same arguments elsewhere reuses the arrays.  Banks of the train
split use ``view_width=2`` (the view width only sets the number of rays; the dynamics,
time limits and oracle are the same), which keeps them cheap.
"""

import pytest

import envs


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
