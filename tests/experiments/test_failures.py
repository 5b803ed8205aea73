"""experiments.failures: the selected model replays a run's, and every seed of a sweep's,
test episodes."""

import json

import pytest

from cli_helpers import SEED, cli_error


# Cheap in-process CLI calls for every test of this module (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("cheap_experiments")


@pytest.mark.slow
def test_failures_of_a_run_replay_its_test_episodes(finished_run, tmp_path, capsys):
    """experiments.failures: the selected model plays the run's own test episodes (its SR
    again), every episode ends one way, and in single rooms every start is in the
    target's room; nothing is replaced without --overwrite."""
    from experiments import failures

    report = failures.main(failures.Args(run=finished_run, out=tmp_path))
    ((seed,),) = report.values()
    tested = json.loads((finished_run / "results_test.json").read_text())["results"]["overall"]["SR"]
    every = seed["all"]
    assert seed["seed"] == SEED and 100 * every["success"] == pytest.approx(tested)
    assert every["success"] + every["failed Done"] + every["time-out"] == pytest.approx(1.0)
    assert seed["start away"]["episodes"] == 0 and seed["start in target room"]["episodes"] == every["episodes"]
    assert (tmp_path / "failures.md").read_text().startswith("# How the episodes end")
    assert json.loads((tmp_path / "failures.json").read_text())["methods"]["a3c+foresit"][0]["all"] == every
    assert "exists; pass --overwrite" in cli_error(failures.cli, ["--run", finished_run, "--out", tmp_path], capsys)
    assert "--methods is for a sweep" in cli_error(failures.cli, ["--run", finished_run, "--methods", "a3c"], capsys)


@pytest.mark.slow
def test_failures_of_a_sweep_replay_every_seeds_test_episodes(tiny_sweep, tmp_path):
    """experiments.failures --run SWEEP: every finished method and seed, each success share
    the seed's own test SR (results.json)."""
    from experiments import failures

    report = failures.main(failures.Args(run=tiny_sweep, out=tmp_path))
    assert list(report) == ["a3c", "a3c+foresit"]
    for method, per_seed in report.items():
        results = json.loads((tiny_sweep / "methods" / method / "results.json").read_text())["results"]
        assert [r["seed"] for r in per_seed] == [r["seed"] for r in results] == [SEED, SEED + 1]
        for mine, theirs in zip(per_seed, results):
            assert 100 * mine["all"]["success"] == pytest.approx(theirs["selected"]["overall"]["SR"], abs=1e-4)
