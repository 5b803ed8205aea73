"""experiments.probe: a run's probes reproduce its test SR, and a sweep arm's checkpoints
are probed."""

import dataclasses
import json
import shutil

import pytest

from cli_helpers import SEED, cli_error, sweep_args
from experiments import sweep
from experiments.running import sweeps
from experiments import rundir


# Cheap in-process CLI calls for every test of this module (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("cheap_experiments")


@pytest.mark.slow
def test_probe_of_a_run_reproduces_its_test_sr_and_reports_every_probe(finished_run, tmp_path, capsys):
    """`experiments.probe --run`: the `trained` condition is the run's own test evaluation
    (the same model, episodes and noise: the same SR as results_test.json); the other
    conditions, f_w's fit and the sub-goal histogram are reported; nothing is replaced
    without --overwrite."""
    from experiments import probe

    run = tmp_path / "run"
    shutil.copytree(finished_run, run)
    episodes = rundir.read_run_info(run)["schedule"]["test_episodes_per_room"]
    report = probe.main(probe.Args(run=run, episodes_per_room=episodes, windows=30))
    (seed,) = report["a3c+foresit"]
    assert seed["seed"] == SEED
    tested = json.loads((run / "results_test.json").read_text())["results"]["overall"]["SR"]
    assert seed["sr"]["trained"] == pytest.approx(tested)
    assert set(seed["sr"]) == {"trained", "noise off", "untrained f_w", "shuffled", "shuffled, noise off"}
    assert all(0.0 <= v <= 100.0 for v in seed["sr"].values())
    sub = seed["items"]["subgoal"]
    assert sub["episodes"] > 0 and sum(sub["shares"]) == pytest.approx(1.0)
    md = (run / "probe.md").read_text()
    for text in ("## a3c+foresit (seeds 3)", "| shuffled |", "t*/T 0.8-1.0"):
        assert text in md, text
    assert json.loads((run / "probe.json").read_text())["methods"]["a3c+foresit"][0]["sr"] == seed["sr"]
    assert "exists; pass --overwrite" in cli_error(probe.cli, ["--run", run], capsys)
    assert "not a run folder" in cli_error(probe.cli, ["--run", tmp_path], capsys)


@pytest.mark.slow
def test_a_sweep_arm_trains_its_own_config_and_is_probed_from_its_checkpoints(tmp_path):
    """`sweep --methods 'a3c+foresit@imagination_input=encoder'`: the arm's seeds train with
    i_tau in the encoder (its parameters have the embedding), its folder's checkpoints
    restore (`probe`), and the probe reads every seed."""
    from experiments import probe

    arm = "a3c+foresit@imagination_input=encoder"
    out = tmp_path / "sweep"
    sweep.main(dataclasses.replace(sweep_args(out), methods=(arm,)))
    report = probe.main(probe.Args(run=out, episodes_per_room=2, windows=4))
    assert [r["seed"] for r in report[arm]] == [SEED, SEED + 1]
    args = rundir.args_from_saved(sweep.Args, rundir.read_json(out / "sweep.json"), methods=(arm,), out=out)
    config, _, states, _ = sweeps.load_method(arm, args, out / "methods" / arm)
    assert config.imagination_input == "encoder" and "imagination_embed" in states.params["params"]["encoder"]
