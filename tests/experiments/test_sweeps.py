"""experiments.running.sweeps: the episodes per room of a run or sweep folder, or the user's."""

import pytest

from experiments import errors


# Cheap in-process CLI calls for every test of this module (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("cheap_experiments")


def test_episodes_per_room_is_the_folders_own_or_the_users(tmp_path):
    """One function answers for evaluate, failures and paper: a run folder's schedule, a
    sweep's (its override, else the preset's), or the user's number, within its bounds."""
    from test_fuzz import started_run

    from experiments.running import presets, sweeps
    from experiments import rundir

    _, tiny = presets.preset("tiny", "a3c+foresit")
    run = started_run(tmp_path / "run")
    assert sweeps.episodes_per_room(run, "test") == tiny.test_episodes_per_room
    assert sweeps.episodes_per_room(run, "val") == tiny.val_episodes_per_room
    assert sweeps.episodes_per_room(run, "val", given=3) == 3
    sweep = tmp_path / "sweep"
    sweep.mkdir()
    rundir.write_started_args(
        sweep / "sweep.json",
        sweeps.Sweep(methods=("a3c",), preset="tiny", seeds=2, out=sweep, test_episodes_per_room=7),
        (),
    )
    assert sweeps.episodes_per_room(sweep, "test", "a3c") == 7
    assert sweeps.episodes_per_room(sweep, "val", "a3c") == tiny.val_episodes_per_room
    for bad in (0, presets.MAX_EPISODES + 1):
        with pytest.raises(errors.UserError, match=r"--episodes-per-room must lie in 1\.\."):
            sweeps.episodes_per_room(run, "test", given=bad)
