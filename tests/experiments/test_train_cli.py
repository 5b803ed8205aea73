"""experiments.train, the program: the run folder it writes, resume after a kill (bit
identical), a resume on another platform, overwrite protection, the non-finite stop, strict
JSON, one-line errors (in-process and from the shell), the folder format before runs had one,
and Config flags that reach the run.  (The run folder's machinery is tests/experiments/test_run.py.)
"""

import dataclasses
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import train_helpers as H
from cli_helpers import SEED, cli_error, restore_latest, run_config, snapshot, strict_json, tiny_args, validations
from experiments import evaluate as evaluate_cli
from experiments import train as train_cli
from experiments.running import checkpoint, numerics, presets, selection
from experiments import rundir
from experiments.running.run import RUN_FORMAT

REPO = Path(__file__).resolve().parents[2]

# Cheap in-process CLI calls for every test of this module (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("cheap_experiments")


@pytest.mark.slow
def test_finished_run_folder(finished_run):
    info = rundir.read_run_info(finished_run)
    assert (info["method"], info["preset"], info["seeds"], info["format"]) == (
        "a3c+foresit",
        "tiny",
        [SEED],
        RUN_FORMAT,
    )
    progress = rundir.read_json(finished_run / "progress.json")
    assert progress["numerics"] == [{"from_update": 0, "platform": numerics.fingerprint()}]
    rows = rundir.read_rows(finished_run / "metrics")
    assert [r["update"] for r in rows] == [1, 2, 3, 4]
    assert all(np.isfinite(r["losses/total_loss"]) for r in rows)
    # Running totals: ended episodes, useful frames (packed windows: every step is useful).
    assert rows[-1]["episodes"] == sum(r["charts/episodes"] for r in rows) > 0
    assert rows[-1]["frames"] == rows[-1]["stepped_frames"] == 4 * 4 * 30
    assert [v["update"] for v in validations(finished_run)] == [2, 4]
    (result,) = rundir.read_json(finished_run / "results.json")["results"]
    assert [v["SR"] for v in result["validation"]] == [v["SR"] for v in validations(finished_run)]
    assert result["training_success_rate"] == [r["charts/success_rate"] for r in rows]
    results = json.loads((finished_run / "results_test.json").read_text())
    assert results["selected_update"] == result["selected_update"]
    assert results["results"] == {k: v for k, v in result["selected"].items() if k != "by_length"}
    assert results["selected_update"] in (2, 4)
    assert set(results["results"]) == {"bathroom", "overall"}
    assert results["results"]["overall"]["episodes"] == 2
    for name in ("results_test.md", "learning_curve.png", "metrics.csv"):
        assert (finished_run / name).stat().st_size > 0
    step, steps, state, best = restore_latest(finished_run)
    assert (step, steps) == (4, [2, 4])
    assert int(state.update) == 4
    H.assert_tree_finite((state, best))


@pytest.mark.slow
def test_resume_after_a_kill_ends_bit_identical_to_an_uninterrupted_run(finished_run, tmp_path):
    """train's own part of a resume (the run's is tests/experiments/test_run.py): its metrics rows."""
    out = tmp_path / "interrupted"
    assert train_cli.main(tiny_args(out, stop_after_chunks=1)) == {"stopped_at": 2}
    assert not (out / "results_test.json").exists()
    # After the metrics of update 3 were written but before its checkpoint: the resumed
    # run must drop that row and redo update 3.
    stale = dict(rundir.read_rows(out / "metrics")[-1], update=3)
    rundir.append_rows(out / "metrics", [stale])
    # The run folder alone says what to resume (method, preset and seed are not repeated).
    train_cli.main(train_cli.Args(out=out, resume=True, progress=False))

    for name in ("metrics.csv", "metrics.jsonl", "progress.json", "results.json", "results_test.json"):
        assert (out / name).read_text() == (finished_run / name).read_text(), name
    step, steps, *resumed = restore_latest(out)
    ref_step, ref_steps, *reference = restore_latest(finished_run)
    assert (step, steps) == (ref_step, ref_steps)
    H.assert_trees_bitwise_equal(resumed, reference)


@pytest.mark.slow
def test_a_run_resumed_on_another_platform_says_so_and_records_where_each_stretch_ran(finished_run, tmp_path, capsys):
    out = tmp_path / "moved"
    train_cli.main(tiny_args(out, stop_after_chunks=1))
    progress = rundir.read_json(out / "progress.json")
    elsewhere = {**numerics.fingerprint(), "jaxlib": "0.0.1"}  # as if started on another machine
    rundir.write_json(out / "progress.json", {**progress, "numerics": [{"from_update": 0, "platform": elsewhere}]})
    capsys.readouterr()
    train_cli.main(train_cli.Args(out=out, resume=True, progress=False))
    err = capsys.readouterr().err
    assert "warning: a3c+foresit: continuing on another platform than updates 0-2 were trained on" in err
    assert rundir.read_json(out / "progress.json")["numerics"] == [
        {"from_update": 0, "platform": elsewhere},
        {"from_update": 2, "platform": numerics.fingerprint()},
    ]
    # (Here it is this machine all along: the numbers are still the uninterrupted run's.)
    assert (out / "results_test.json").read_text() == (finished_run / "results_test.json").read_text()


@pytest.mark.slow
def test_overwrite_replaces_a_run_and_same_seed_gives_the_same_run(finished_run, tmp_path):
    out = tmp_path / "copy"
    shutil.copytree(finished_run, out)
    (out / "stray.txt").write_text("from the old run")
    train_cli.main(tiny_args(out, overwrite=True))
    assert not (out / "stray.txt").exists()
    assert (out / "metrics.csv").read_text() == (finished_run / "metrics.csv").read_text()
    assert (out / "results_test.json").read_text() == (finished_run / "results_test.json").read_text()


@pytest.mark.slow
def test_existing_folders_are_never_overwritten_without_a_flag(finished_run, tmp_path, capsys):
    before = snapshot(finished_run)
    line = cli_error(train_cli.cli, ["--preset", "tiny", "--out", finished_run], capsys)
    assert "already exists" in line and "--resume" in line and "--overwrite" in line
    # A bad value with --overwrite fails before anything is deleted.
    line = cli_error(
        train_cli.cli, ["--preset", "tiny", "--out", finished_run, "--overwrite", "--num-lanes", "0"], capsys
    )
    assert "num_lanes must be >= 1" in line
    assert snapshot(finished_run) == before

    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "thesis.tex").write_text("months of work")
    for flags in ([], ["--overwrite"]):
        line = cli_error(train_cli.cli, ["--preset", "tiny", "--out", notes, *flags], capsys)
    assert "not a run folder" in line and "refusing to delete" in line
    line = cli_error(train_cli.cli, ["--out", notes, "--resume"], capsys)
    assert "not a run folder" in line
    assert snapshot(notes) == {"thesis.tex": b"months of work"}


@pytest.mark.slow
def test_a_run_validated_under_another_selection_protocol_is_not_resumed(finished_run, tmp_path, capsys):
    assert rundir.read_json(finished_run / "progress.json")["selection_protocol"] == selection.PROTOCOL_VERSION
    out = tmp_path / "older"
    shutil.copytree(finished_run, out)
    progress = rundir.read_json(out / "progress.json")
    rundir.write_json(out / "progress.json", {**progress, "selection_protocol": selection.PROTOCOL_VERSION - 1})
    before = snapshot(out)
    line = cli_error(train_cli.cli, ["--out", out, "--resume"], capsys)
    assert f"validated under selection protocol {selection.PROTOCOL_VERSION - 1}" in line and "start it again" in line
    assert snapshot(out) == before


@pytest.mark.slow
def test_non_finite_loss_stops_training_naming_the_update_and_keeps_the_last_good_checkpoint(tmp_path, capsys):
    out = tmp_path / "diverging"
    train_cli.main(tiny_args(out, stop_after_chunks=1))
    # Poison the rewards from update 3 on (same shapes and types: the compiled chunk is
    # reused): every loss of the second chunk is NaN.
    trainer = H.cached_trainer(run_config(out))
    good = trainer.env_params
    trainer.env_params = good.replace(step_penalty=float("nan"))
    capsys.readouterr()
    try:
        with pytest.raises(SystemExit) as exc:
            train_cli.main(train_cli.Args(out=out, resume=True, progress=False))
    finally:
        trainer.env_params = good
    assert exc.value.code == 1
    message = capsys.readouterr().err.strip().splitlines()[-1]
    assert "non-finite loss at update 3" in message and "last checkpoint (update 2, finite)" in message
    step, steps, *state = restore_latest(out)
    assert (step, steps) == (2, [2])
    H.assert_tree_finite(state)
    assert [r["update"] for r in rundir.read_rows(out / "metrics")] == [1, 2]
    assert not (out / "results_test.json").exists()


@pytest.mark.slow
def test_run_files_are_strict_json(finished_run):
    for path in [finished_run / "run.json", finished_run / "progress.json", *finished_run.glob("results*.json")]:
        strict_json(path.read_text())
    for line in (finished_run / "metrics.jsonl").read_text().splitlines():
        strict_json(line)


TRAIN_ERRORS = [
    (["--method", "bogus"], ["unknown method 'bogus'", "a3c, a3c+foresit, a3c+rnd, a3c+att, a3c+int, a3c+maml"]),
    (["--method", "a3c+maml+org"], ["needs setup 'org'"]),
    (["--method", "a3c+org+foresit"], ["needs setup 'org'"]),
    (["--setup", "thor"], ["setup must be one of"]),
    (["--preset", "huge"], ["unknown preset 'huge'", "tiny, quick, house, paper"]),
    (["--num-lanes", "0"], ["num_lanes must be >= 1"]),
    (["--num-updates", "0"], ["num_updates must be >= 1"]),
    (["--learning-rate", "-0.001"], ["learning_rate must be > 0"]),
    (["--learning-rate", "0"], ["learning_rate must be > 0"]),
    (["--chunk-updates", "0"], ["chunk_updates must be >= 1"]),
    (["--val-episodes-per-room", "0"], ["val_episodes_per_room must be >= 1"]),
    (["--resume"], ["is not there; nothing to resume"]),
    (["--resume", "--overwrite"], ["exclude each other"]),
    # issue 71: checked before anything is written (no run.json, no .lock left behind)
    (["--room-types", "garage"], ["unknown room type 'garage'"]),
    (["--seed", str(2**70)], ["seeds must lie in 0..2**63-1"]),
    (["--seed", "-1"], ["seeds must lie in 0..2**63-1"]),
]


@pytest.mark.parametrize("argv, expected", TRAIN_ERRORS, ids=[" ".join(a) for a, _ in TRAIN_ERRORS])
def test_train_rejects_bad_input_in_one_line(argv, expected, tmp_path, capsys):
    out = tmp_path / "new_run"
    line = cli_error(train_cli.cli, ["--preset", "tiny", "--out", out, *argv], capsys)
    for text in expected:
        assert text in line
    assert not out.exists()  # nothing was created for a command that failed


def test_bad_method_from_the_shell_is_one_line_without_traceback(tmp_path):
    """The real command line (a fresh interpreter); it fails before anything compiles."""
    out = tmp_path / "x"
    proc = subprocess.run(
        [sys.executable, "-m", "experiments.train", "--method", "bogus", "--out", str(out)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert lines == [lines[0]] and lines[0].startswith("error: unknown method 'bogus'"), proc.stderr
    assert "valid methods: a3c, a3c+foresit" in lines[0]
    assert not out.exists()


def as_legacy_train_folder(run: Path, out: Path) -> None:
    """The folder train wrote before runs had one format, made from a run of this one: run.json
    with one "seed", checkpoints/ of the bare training state, best/ of the selected model."""
    info = rundir.read_run_info(run)
    step, _, state, best = restore_latest(run)
    (result,) = rundir.read_json(run / "results.json")["results"]
    out.mkdir()
    old = {k: v for k, v in info.items() if k not in ("format", "seeds", "arm")}
    rundir.write_run_info(out, {**old, "arm": info["arm"], "seed": info["seeds"][0]})
    checkpoint.save(checkpoint.checkpoint_manager(out / "checkpoints", 2), step, state)
    checkpoint.save(checkpoint.checkpoint_manager(out / "best", 1), result["selected_update"], best)
    shutil.copy(run / "results_test.json", out / "results_test.json")


@pytest.mark.slow
def test_a_train_folder_of_the_format_before_still_reads_and_is_refused_a_resume(finished_run, tmp_path, capsys):
    from experiments import probe

    out = tmp_path / "legacy"
    as_legacy_train_folder(finished_run, out)
    trained = json.loads((out / "results_test.json").read_text())
    np.testing.assert_equal(evaluate_cli.main(evaluate_cli.Args(run=out, overwrite=True)), trained["results"])
    (seed,) = probe.models_of_run(out)["a3c+foresit"]
    (new,) = probe.models_of_run(finished_run)["a3c+foresit"]
    assert seed.seed == new.seed == SEED
    H.assert_trees_bitwise_equal((seed.state, seed.selected), (new.state, new.selected))
    before = snapshot(out)
    line = cli_error(train_cli.cli, ["--out", out, "--resume"], capsys)
    assert "before runs had one format" in line and "train it anew" in line, line
    info = rundir.read_run_info(finished_run)
    arm = tmp_path / "arm"  # a run folder of two seeds: a sweep's arm, not train's
    arm.mkdir()
    rundir.write_run_info(arm, {**info, "seeds": [SEED, SEED + 1]})
    assert "a sweep's arm (2 seed(s))" in cli_error(train_cli.cli, ["--out", arm, "--resume"], capsys)
    arm = tmp_path / "sweep" / "methods" / "a3c+foresit"  # one seed, but its sweep's to continue
    arm.mkdir(parents=True)
    rundir.write_run_info(arm, info)
    (tmp_path / "sweep" / "sweep.json").write_text("{}")
    assert "a sweep's arm (1 seed(s))" in cli_error(train_cli.cli, ["--out", arm, "--resume"], capsys)
    assert {k: v for k, v in snapshot(out).items() if k != rundir.LOCK_FILE} == {
        k: v for k, v in before.items() if k != rundir.LOCK_FILE
    }


@pytest.mark.slow
def test_config_flags_reach_the_run_and_resume_refuses_other_values(tmp_path, capsys):
    out = tmp_path / "gamma"
    train_cli.main(
        dataclasses.replace(
            tiny_args(out, stop_after_chunks=1), config=presets.TrainConfigFields(gamma=0.9, entropy_coef=0.02)
        )
    )
    assert (run_config(out).gamma, run_config(out).entropy_coef) == (0.9, 0.02)
    line = cli_error(train_cli.cli, ["--out", out, "--resume", "--gamma", "0.5"], capsys)
    assert "--gamma 0.5 (the run has 0.9)" in line
    train_cli.cli(["--out", str(out), "--resume", "--gamma", "0.9", "--no-progress"])  # the run's own value: fine
    assert rundir.read_json(out / "results_test.json")["results"]
