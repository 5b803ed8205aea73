"""The experiments programs' shared training fixtures: a tiny run and a tiny sweep, each
trained once a session (on the one xdist worker their tests go to: tests/conftest.py's
SHARED_TRAINING_FIXTURES), under the cheap in-process patch (`train_helpers.patch_for_experiments`):
the module's own when its `cheap_experiments` holds already, else one of their own for as long as
they train."""

import contextlib

import pytest

import train_helpers as H
from cli_helpers import sweep_args, tiny_args
from experiments import sweep
from experiments import train as train_cli


@contextlib.contextmanager
def _cheap():
    """The cheap patch while a fixture trains (the module's, when one holds)."""
    import foresit_jax.train as train

    if train.make_trainer is H._make_trainer_cached:  # a module's cheap_experiments holds
        yield
        return
    with pytest.MonkeyPatch.context() as mp:
        H.patch_for_experiments(mp)
        yield


@pytest.fixture(scope="session")
def finished_run(tmp_path_factory):
    """An uninterrupted tiny run (4 updates in 2 chunks): the reference of the resume test."""
    out = tmp_path_factory.mktemp("runs") / "uninterrupted"
    with _cheap():
        train_cli.main(tiny_args(out))
    return out


@pytest.fixture(scope="session")
def tiny_sweep(tmp_path_factory):
    """Two methods, two seeds of a tiny sweep on this process's devices (one CPU device)."""
    out = tmp_path_factory.mktemp("sweeps") / "one_device"
    with _cheap():
        sweep.main(sweep_args(out))
    return out
