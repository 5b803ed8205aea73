"""experiments.evaluate, the program: it reproduces the test results of training, evaluates
the last checkpoint and other protocols to their own files, and refuses bad input in one line."""

import json
import shutil

import numpy as np
import pytest

from cli_helpers import cli_error, validations
from experiments import evaluate as evaluate_cli


# Cheap in-process CLI calls for every test of this module (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("cheap_experiments")


@pytest.mark.slow
def test_evaluate_rejects_bad_input_in_one_line(finished_run, tmp_path, capsys):
    nothing = tmp_path / "nothing"
    nothing.mkdir()
    assert "not a run folder" in cli_error(evaluate_cli.cli, ["--run", nothing], capsys)
    assert "--split must be val or test" in cli_error(
        evaluate_cli.cli, ["--run", finished_run, "--split", "train"], capsys
    )
    for n in ("0", "-3"):
        line = cli_error(evaluate_cli.cli, ["--run", finished_run, "--episodes-per-room", n], capsys)
        assert "--episodes-per-room must lie in 1..100,000, got" in line
    # train wrote results_test.json: evaluating the same model again needs --overwrite.
    assert "--overwrite" in cli_error(evaluate_cli.cli, ["--run", finished_run], capsys)


@pytest.mark.slow
def test_evaluate_cli_reproduces_the_test_results_of_training(finished_run, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(finished_run, out)
    trained = json.loads((out / "results_test.json").read_text())
    # The model selected on validation, from the last checkpoint, on the run's own test episodes.
    results = evaluate_cli.main(evaluate_cli.Args(run=out, overwrite=True))
    np.testing.assert_equal(results, trained["results"])  # (NaN == NaN here)
    written = json.loads((out / "results_test.json").read_text())
    np.testing.assert_equal(written["results"], trained["results"])
    assert written["which"] == "best"
    # On val, the validation episodes of the selected model's update: its row again.
    val = evaluate_cli.main(evaluate_cli.Args(run=out, split="val"))
    row = next(r for r in validations(out) if r["update"] == trained["selected_update"])
    assert val["overall"]["episodes"] == row["episodes"] and val["overall"]["SR"] == pytest.approx(row["SR"])
    # The last checkpoint goes to its own files and leaves the others alone.
    last = evaluate_cli.main(evaluate_cli.Args(run=out, which="last", split="val", episodes_per_room=2))
    assert set(last) == {"bathroom", "overall"} and last["overall"]["episodes"] == 2
    assert (out / "results_val_last.json").exists() and (out / "results_val_last.md").exists()
    # Another protocol than the method's own, from the command line, to its own files.
    evaluate_cli.cli(["--run", str(out), "--split", "val", "--episodes-per-room", "2", "--actions", "greedy"])
    assert (out / "results_val_best_greedy.json").exists()
