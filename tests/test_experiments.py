"""experiments: run folders, resume, overwrite protection, non-finite losses, one-line
errors, and every command of the README and docs/usage.md at a tiny size.

The CLIs are called in-process (`main(Args(...))`, `cli(argv)`): a subprocess re-imports
jax and recompiles everything.  `train_helpers.patch_for_experiments` keeps them cheap
(bathroom-only `tiny` preset, one Trainer per config so every `main()` reuses one
compiled chunk, fast XLA compilation); what the CLIs do is unchanged.
"""

import dataclasses
import importlib
import importlib.util
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest
import tyro

import train_helpers as H
from experiments import evaluate as evaluate_cli
from experiments import sweep
from experiments import train as train_cli
from experiments.reporting import cvae_comparison, figures, report, tables
from experiments import errors
from experiments.running import checkpoint, numerics, presets, progress, selection, sweeps
from experiments import rundir
from experiments.errors import RunNotFound
from experiments.running.run import COUNTS, RUN_FORMAT, initial_states
from foresit_jax.config import Config

REPO = Path(__file__).resolve().parents[1]
SEED = 3


# Cheap in-process CLI calls for every test of this module (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("cheap_experiments")


def tiny_args(out: Path, **kwargs) -> train_cli.Args:
    return train_cli.Args(method="a3c+foresit", preset="tiny", seed=SEED, out=out, progress=False, **kwargs)


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory, cheap_experiments):
    """An uninterrupted tiny run (4 updates in 2 chunks): the reference of the resume test."""
    out = tmp_path_factory.mktemp("runs") / "uninterrupted"
    train_cli.main(tiny_args(out))
    return out


def run_config(out: Path) -> Config:
    return Config(**rundir.read_run_info(out)["config"])


def restore_latest(out: Path):
    """(latest step, every step kept, the training state and the selected model there) of a
    one-seed run folder."""
    config = run_config(out)
    manager = checkpoint.checkpoint_manager(out / "checkpoints", 100)
    step = manager.latest_step()
    like = initial_states(H.cached_trainer(config), [SEED])
    restored = checkpoint.restore(manager, step, {"states": like[0], "best": like[1]})
    state, best = jax.tree.map(lambda x: x[0], (restored["states"], restored["best"]))
    return step, manager.all_steps(), state, best


def validations(out: Path) -> list[dict]:
    """A one-seed run's validations (progress.json)."""
    (history,) = rundir.read_json(out / "progress.json")["history"]
    return history


def snapshot(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def cli_error(cli, argv, capsys) -> str:
    """Run a CLI that must fail: exit status 2 and exactly one line on stderr, no traceback."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        cli([str(a) for a in argv])
    err = capsys.readouterr().err
    assert exc.value.code == 2, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err
    return lines[0]


# ---------------------------------------------------------------------- training runs
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
    """train's own part of a resume (the run's is tests/test_run.py): its metrics rows."""
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


def strict_json(text: str):
    """json.loads that refuses NaN/Infinity (not JSON, though Python writes them by default)."""

    def refuse(token):
        raise ValueError(f"non-strict JSON token {token}")

    return json.loads(text, parse_constant=refuse)


@pytest.mark.slow
def test_run_files_are_strict_json(finished_run):
    for path in [finished_run / "run.json", finished_run / "progress.json", *finished_run.glob("results*.json")]:
        strict_json(path.read_text())
    for line in (finished_run / "metrics.jsonl").read_text().splitlines():
        strict_json(line)


# ---------------------------------------------------------------------- shared pieces
def test_json_writes_nan_as_null(tmp_path):
    @dataclasses.dataclass(frozen=True)
    class Where:
        out: Path
        sizes: tuple

    results = {
        "overall": {"SR": 12.5, "SR>=5": float("nan"), "SPL>=5": np.float32("nan"), "episodes": np.int64(8)},
        "bad": [float("inf"), -float("inf")],
        "args": Where(Path("runs/x"), (1, 2)),
    }
    rundir.write_json(tmp_path / "r.json", results)
    text = (tmp_path / "r.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    assert strict_json(text) == {
        "overall": {"SR": 12.5, "SR>=5": None, "SPL>=5": None, "episodes": 8},
        "bad": [None, None],
        "args": {"out": "runs/x", "sizes": [1, 2]},
    }
    # Rows: JSONL strict, CSV as before (nan), and a row read back (null -> None) is
    # written to CSV the same way (a resume rewrites the CSV from the JSONL).
    row = {"update": 1, "SR": 50.0, "SR>=5": float("nan")}
    rundir.append_rows(tmp_path / "validation", [row])
    (back,) = rundir.read_rows(tmp_path / "validation")
    assert back == {"update": 1, "SR": 50.0, "SR>=5": None}
    rundir.append_rows(tmp_path / "again", [back])
    assert (
        (tmp_path / "again.csv").read_text()
        == (tmp_path / "validation.csv").read_text()
        == "update,SR,SR>=5\n1,50.0,nan\n"
    )
    with pytest.raises(TypeError, match="not JSON serialisable"):
        rundir.to_json({"x": object()})


def test_markdown_table_of_a_hand_written_table():
    rows = [["a3c", "12.50", 250], ["a3c+foresit", "n/a", 7]]
    assert tables.markdown_table(rows, ["method", "SR", "episodes"]) == (
        "| method | SR | episodes |\n|---|---|---|\n| a3c | 12.50 | 250 |\n| a3c+foresit | n/a | 7 |"
    )
    assert tables.markdown_table(rows, ["method", "SR", "episodes"], align="<>>") == (
        "| method      |    SR | episodes |\n"
        "|-------------|-------|----------|\n"
        "| a3c         | 12.50 |      250 |\n"
        "| a3c+foresit |   n/a |        7 |"
    )
    assert tables.markdown_table([], ["x"]) == "| x |\n|---|"
    with pytest.raises(ValueError, match="2 cells for 3 columns"):
        tables.markdown_table([["a", "b"]], ["x", "y", "z"])
    with pytest.raises(ValueError, match="align"):
        tables.markdown_table(rows, ["method", "SR", "episodes"], align="<>")


def test_reports_use_the_one_table_writer():
    results = {"overall": {"SPL": 10.0, "SR": 20.0, "SPL>=5": float("nan"), "SR>=5": None, "episodes": 4}}
    assert tables.results_markdown(results, "T", level=2) == (
        "## T\n\n| rooms | SPL | SR | SPL>=5 | SR>=5 | episodes |\n|---|---|---|---|---|---|\n"
        "| overall | 10.00 | 20.00 | n/a | n/a | 4 |\n"
    )
    rows = report.table(
        {
            "a3c": [{"overall": {"SPL": 1.0, "SR": 2.0, "SPL>=5": 3.0, "SR>=5": 4.0}}] * 2,
            "b": [{"overall": {"SPL": 1.0, "SR": 10.0, "SPL>=5": None, "SR>=5": 4.0}}],
        }
    )
    assert report.table_markdown(rows, "T1") == (
        "# T1\n\n| Method | SPL | SR | SPL>=5 | SR>=5 |\n|---|---|---|---|---|\n"
        "| a3c | 1.00 ± 0.00 [1.0, 1.0] | 2.00 ± 0.00 [2.0, 2.0] | 3.00 ± 0.00 [3.0, 3.0] | 4.00 ± 0.00 [4.0, 4.0] |\n"
        "| b | 1.00 | 10.00 | n/a | 4.00 |\n"
        "(mean ± sample std [95% confidence interval, Student t] over seeds)\n"
    )


def test_sweep_pairs_every_method_with_the_first_seed_by_seed():
    result = lambda sr, spl: {"overall": {"SR": sr, "SPL": spl}}  # noqa: E731
    md = report.paired_markdown(
        {
            "a3c": [result(1.0, 0.0), result(2.0, 0.0), result(3.0, 0.0)],
            "b": [result(2.0, 1.0), result(4.0, 1.0), result(5.0, 1.0)],
        }
    )
    # SR differences 1, 2, 2: mean 5/3, t = 5 with 2 dof, p = 1 - 5 / sqrt(27) = 0.038,
    # interval 5/3 -+ 4.303 / 3; SPL differences all 1: no spread, no p.
    assert (
        "| b - a3c | +1.67 [+0.2, +3.1] | 0.038 | holds | +1.00 [+1.0, +1.0] | n/a | cannot tell at this budget |" in md
    )


def test_write_csv(tmp_path):
    path = tmp_path / "t.csv"
    rundir.write_csv(path, [{"method": "a3c", "SR": 1.5}])
    rundir.write_csv(path, [{"method": "b", "SR": None}], append=True)
    assert list(csv_rows(path)) == [{"method": "a3c", "SR": "1.5"}, {"method": "b", "SR": "nan"}]
    rundir.write_csv(path, [{"x": 1}])  # without append: replaced
    assert path.read_text() == "x\n1\n"


def test_the_format_reads_a_sweep_folder_and_says_what_is_missing(tmp_path):
    """rundir's reads on a hand-made sweep folder: one finished arm, one started, one empty."""
    sweep = tmp_path / "sweep"
    with pytest.raises(errors.UserError, match="is not a sweep folder"):
        rundir.sweep_results(sweep)
    sweep.mkdir()
    (sweep / rundir.SWEEP_FILE).write_text("{}")
    done, started = rundir.arm_folder(sweep, "b"), rundir.arm_folder(sweep, "a")
    for folder in (done, started, rundir.arm_folder(sweep, "c")):
        folder.mkdir(parents=True)
    with pytest.raises(errors.UserError, match="has no finished method yet"):
        rundir.sweep_results(sweep)
    rundir.write_json(done / rundir.RESULTS_FILE, {"updates": 4, "results": [{"seed": 3}, {"seed": 1}]})
    rundir.write_json(started / rundir.PROGRESS_FILE, {"done": 2})
    assert rundir.sweep_results(sweep) == {"b": [{"seed": 3}, {"seed": 1}]}
    assert [f.name for f in rundir.arm_folders(sweep)] == ["a", "b", "c"]
    assert rundir.finished_seeds(done) == [3, 1] and rundir.finished_seeds(started) == []
    assert rundir.read_results(started) is None and rundir.read_progress(started) == {"done": 2}
    with pytest.raises(errors.RunNotFound, match="has not finished"):
        rundir.read_results(started, required=True)
    assert rundir.in_sweep(done) and not rundir.in_sweep(tmp_path) and rundir.is_sweep(sweep)
    assert rundir.checkpoint_at(done, 4) == done / "checkpoints" / "4"


@pytest.mark.parametrize("marker, kind", [(rundir.RUN_FILE, "run"), ("sweep.json", "sweep")])
def test_prepare_run_dir_never_deletes_what_it_did_not_write(tmp_path, marker, kind):
    out = tmp_path / "out"
    rundir.prepare_run_dir(out, resume=False, overwrite=False, marker=marker, kind=kind)
    assert out.is_dir()
    rundir.prepare_run_dir(out, resume=False, overwrite=False, marker=marker, kind=kind)  # empty: fine
    (out / "notes.txt").write_text("mine")
    for overwrite, says in ((False, "already exists and is not empty"), (True, f"not a {kind} folder")):
        with pytest.raises(errors.UserError, match=says) as e:
            rundir.prepare_run_dir(out, resume=False, overwrite=overwrite, marker=marker, kind=kind)
        assert "\n" not in str(e.value)  # one line
    with pytest.raises(errors.UserError, match=f"not a {kind} folder .*nothing to resume"):
        rundir.prepare_run_dir(out, resume=True, overwrite=False, marker=marker, kind=kind)
    with pytest.raises(RunNotFound, match="no such is not there; nothing to resume"):
        rundir.prepare_run_dir(tmp_path / "no such", resume=True, overwrite=False, marker=marker, kind=kind)
    assert (out / "notes.txt").read_text() == "mine"
    (out / marker).write_text("{}")
    with pytest.raises(errors.UserError, match="--overwrite"):
        rundir.prepare_run_dir(out, resume=False, overwrite=False, marker=marker, kind=kind)
    rundir.prepare_run_dir(out, resume=False, overwrite=True, marker=marker, kind=kind)
    assert out.is_dir() and [p.name for p in out.iterdir()] == [rundir.LOCK_FILE]


def test_learning_curve_png_leaves_matplotlib_global_state_alone(tmp_path, monkeypatch):
    import matplotlib

    def no_global_backend(*args, **kwargs):
        raise AssertionError("matplotlib.use called: the global backend must be left alone")

    monkeypatch.setattr(matplotlib, "use", no_global_backend)
    had_pyplot = "matplotlib.pyplot" in sys.modules
    x = np.arange(1, 6)
    figures.learning_curve_png(
        tmp_path / "c.png", {"a": (x, x / 10.0), "b": (x, np.stack([x, x + 1]) / 10.0)}, val_points=[(2, 0.1), (4, 0.3)]
    )
    assert (tmp_path / "c.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert ("matplotlib.pyplot" in sys.modules) == had_pyplot


def test_progress_bar_is_shared_and_without_the_bar_logs_a_line_per_chunk(capsys):
    advance = progress.progress_bar(total=5, initial=1, enabled=False)
    advance(2, {"method": "a3c", "SR": "0.1"})
    advance.at(4)  # inside a chunk: no line
    advance(2, {"method": "a3c", "val SR": "12.5%"})
    advance(0, None)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 2, lines
    assert re.fullmatch(r"\[\d\d:\d\d:\d\d\] 3/5 updates, 0\.0 min: method a3c, SR 0\.1", lines[0]), lines[0]
    assert re.fullmatch(r"\[\d\d:\d\d:\d\d\] 5/5 updates, 0\.0 min: method a3c, val SR 12\.5%", lines[1]), lines[1]
    assert not hasattr(train_cli, "_progress")
    assert train_cli.progress_bar is sweeps.progress_bar is progress.progress_bar
    # Where a resumed run starts: no line, and not counted in the rate (tqdm's `initial`).
    for enabled in (True, False):
        capsys.readouterr()
        advance = progress.progress_bar(total=10, initial=0, enabled=enabled, tty=True)
        advance.skip(6)
        advance.skip(4)  # never back
        assert advance.position() == 6
        advance(2, {"method": "a3c"})
        assert advance.position() == 8
        advance(0, None)
    lines = capsys.readouterr().err.splitlines()  # without the bar: the chunk's line, none for the skip
    assert len(lines) == 1 and " 8/10 updates" in lines[0], lines


@pytest.mark.slow
def test_demo_oracle_plays_the_random_policys_episodes():
    from experiments import demo
    from foresit_jax.evaluate import random_policy_rollout

    env, env_params = H.bathroom_env("test", training=False)
    key = jax.random.PRNGKey(5)
    random = random_policy_rollout(env, env_params, key, 6, 100)
    _, _, oracle, _ = demo.oracle_rollout(env, 6, 100)(env_params, key)
    np.testing.assert_array_equal(random.optimal_length, oracle.optimal_length)  # the same episodes
    assert np.asarray(oracle.success).all() and (np.asarray(oracle.length) == np.asarray(oracle.optimal_length)).all()
    m = demo.metrics(jax.tree.map(np.asarray, oracle))
    assert m["SR"] == m["SPL"] == 100.0 and m["episodes"] == 6


# ---------------------------------------------------------------------- one-line errors
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


def test_buffer_size_below_one_is_refused():
    """(Not a CLI flag; a preset override or a Config.)"""
    with pytest.raises(ValueError, match="buffer_size must be >= 1"):
        presets.preset("tiny", "a3c+foresit", buffer_size=0)


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


SWEEP_EPISODES = dict(val_episodes_per_room=12, test_episodes_per_room=24)  # enough that other keys give other numbers


# ---------------------------------------------------------------------- probes
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


@pytest.mark.slow
def test_sampled_results_of_a_sweep_replay_its_sampled_test_evaluation(tiny_sweep):
    """paper_figures.sampled_results (the report's ORG rows with sampled actions): every finished
    seed's selected model on its own test episodes, actions sampled. a3c is evaluated
    sampled by its protocol, so these are the sweep's own test results again: the same
    models, episodes and keys."""
    from experiments.running import paper_figures

    sampled = paper_figures.sampled_results(tiny_sweep, ["a3c"])
    per_seed = json.loads((tiny_sweep / "methods" / "a3c" / "results.json").read_text())["results"]
    assert [r["seed"] for r in sampled["a3c"]] == [r["seed"] for r in per_seed] == [SEED, SEED + 1]
    for mine, theirs in zip(sampled["a3c"], per_seed):
        for col in ("SR", "SPL"):
            assert mine["overall"][col] == pytest.approx(theirs["selected"]["overall"][col], abs=1e-4), col


def sweep_args(out: Path) -> sweep.Args:
    return sweep.Args(
        methods=("a3c", "a3c+foresit"), seeds=2, preset="tiny", seed=SEED, out=out, progress=False, **SWEEP_EPISODES
    )


@pytest.fixture(scope="module")
def tiny_sweep(tmp_path_factory, cheap_experiments):
    """Two methods, two seeds of a tiny sweep on this process's devices (one CPU device)."""
    out = tmp_path_factory.mktemp("sweeps") / "one_device"
    sweep.main(sweep_args(out))
    return out


@pytest.mark.slow
def test_sweep_seed_i_is_the_run_train_makes_with_seed_i(tiny_sweep, tmp_path):
    """The same protocol in both: seed i of a sweep starts from train --seed i's key,
    validates on its episodes after each chunk, selects the same update and tests on the
    same episodes (equal up to the vmapped program's float rounding, which does not flip
    an outcome at this size); the last model is tested too.  (Enough episodes that other
    keys give other numbers: with a test key or a training key off by one, this fails.)"""
    out, episodes = tiny_sweep, SWEEP_EPISODES
    per_seed = json.loads((out / "results_per_seed.json").read_text())["a3c+foresit"]
    assert [r["seed"] for r in per_seed] == [SEED, SEED + 1]
    trained = [tmp_path / f"train{i}" for i in range(2)]
    for i, run in enumerate(trained):
        train_cli.main(
            train_cli.Args(method="a3c+foresit", preset="tiny", seed=SEED + i, out=run, progress=False, **episodes)
        )
    for r, run in zip(per_seed, trained):
        mine = json.loads((run / "results_test.json").read_text())
        assert r["selected_update"] == mine["selected_update"]
        rows = list(rundir.read_rows(run / "metrics"))
        curve = [row["charts/success_rate"] for row in rows]
        np.testing.assert_allclose(r["training_success_rate"], curve, atol=1e-6)  # the same episodes were trained on
        for name in COUNTS:  # the experience counted is train's, update by update
            assert r["counts"][name] == pytest.approx(sum(row[name] for row in rows)) and r["counts"][name] > 0
        validation = validations(run)
        assert [v["update"] for v in r["validation"]] == [v["update"] for v in validation] == [2, 4]
        np.testing.assert_allclose([v["SR"] for v in r["validation"]], [v["SR"] for v in validation])
        for col in ("SR", "SPL", "episodes"):
            assert r["selected"]["overall"][col] == pytest.approx(mine["results"]["overall"][col], abs=1e-3)
        last = evaluate_cli.main(evaluate_cli.Args(run=run, which="last", overwrite=True))  # on train's test episodes
        for col in ("SR", "SPL"):
            assert r["last"]["overall"][col] == pytest.approx(last["overall"][col], abs=1e-3)
    table = next(csv_rows(out / "table1.csv"))
    assert float(table["SR mean"]) == pytest.approx(np.mean([r["selected"]["overall"]["SR"] for r in per_seed]))
    md = (out / "table1.md").read_text()
    assert "Model selection" in md and f"{SEED}: " in md and f"(update {per_seed[0]['selected_update']})" in md
    assert "### a3c+foresit - a3c, paired per bucket" in md


def test_a_sweeps_table_pairs_each_path_length_bucket_over_seeds():
    """table1.md's section by L^g, against a hand computation: per bucket the mean ± std
    of each method, the mean seed-by-seed difference with its Student-t interval (scipy),
    the test episodes of the first method's seeds; an empty bucket (null) is n/a."""
    from scipy import stats as scipy_stats

    sr = {"a3c": [[60.0, 20.0], [50.0, 30.0], [70.0, 10.0]], "a3c+critic": [[55.0, 30.0], [51.0, 33.0], [60.0, 18.0]]}

    def seed(rates):
        by_length = {
            "1-4": {"SR": rates[0], "SPL": rates[0] / 2, "episodes": 40},
            ">=5": {"SR": rates[1], "SPL": rates[1] / 4, "episodes": 60},
            ">=20": {"SR": None, "SPL": None, "episodes": 0},
        }
        return {"selected": {"by_length": by_length}}

    results = {m: [seed(r) for r in per_seed] for m, per_seed in sr.items()}
    md = report.by_length_markdown(results)
    row = {
        line.split("|")[1].strip(): [c.strip() for c in line.split("|")[2:-1]]
        for line in md.split("### a3c+critic - a3c")[1].splitlines()
        if line.startswith("| ")
    }
    for i, bucket in enumerate(("1-4", ">=5")):
        d = np.array(sr["a3c+critic"])[:, i] - np.array(sr["a3c"])[:, i]
        half = scipy_stats.t.ppf(0.975, 2) * d.std(ddof=1) / np.sqrt(3)
        assert row[bucket][:2] == [
            "120" if i == 0 else "180",
            f"{d.mean():+.1f} [{d.mean() - half:+.1f}, {d.mean() + half:+.1f}]",
        ]
        x = np.array(sr["a3c"])[:, i]
        assert f"| {bucket} | {x.mean():.1f} ± {x.std(ddof=1):.1f} / {x.mean() / (2 if i == 0 else 4):.1f}" in md
    assert row[">=20"][:2] == ["0", "n/a"] and "| >=20 | n/a / n/a | n/a / n/a |" in md
    assert report.by_length_markdown({"a3c": results["a3c"]}) == ""  # nothing to pair


def test_sweep_rejects_bad_input_in_one_line(tmp_path, capsys):
    out = tmp_path / "sweep"
    base = ["--preset", "tiny", "--out", out]
    assert "--seeds must be >= 1" in cli_error(sweep.cli, [*base, "--seeds", "0"], capsys)
    assert "a3c more than once" in cli_error(sweep.cli, [*base, "--methods", "a3c", "a3c+critic", "a3c"], capsys)
    assert "2**63-1" in cli_error(sweep.cli, [*base, "--seed", str(2**63 - 2), "--seeds", "3"], capsys)
    assert "unknown room type" in cli_error(sweep.cli, [*base, "--room-types", "garage"], capsys)
    assert not out.exists()
    assert "unknown method 'bogus'" in cli_error(sweep.cli, [*base, "--methods", "a3c", "bogus"], capsys)
    assert "valid presets" in cli_error(sweep.cli, ["--preset", "huge", "--out", out], capsys)
    assert ">= 1" in cli_error(sweep.cli, [*base, "--test-episodes-per-room", "0"], capsys)
    assert not out.exists()
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "keep.txt").write_text("x")
    assert "refusing to delete" in cli_error(sweep.cli, [*base[:2], "--out", notes, "--overwrite"], capsys)
    assert (notes / "keep.txt").exists()


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


@pytest.mark.slow
def test_a_sweep_spread_over_two_host_devices_equals_the_one_device_sweep(tiny_sweep, tmp_path):
    """The seed axis sharded over 2 forced host devices (a fresh interpreter: the flag
    must precede jax's start): the same selections, validation and test results, and
    training curves equal to float rounding.  In the same interpreter, a3c+maml's sharded
    sweep program lowers (with nn.Conv in L_phi, partitioning its second-order
    convolutions raised NotImplementedError).  Its checkpoint, saved from the 2 devices, is
    read back onto one device, there and in this process (before, it came back spread over
    both there, and failed with orbax's "Topology mismatch" in a 1-device process)."""
    out = tmp_path / "two_devices"
    on_one_device = (
        "assert {d for x in jax.tree.leaves(read[2:]) for d in x.sharding.device_set} == {jax.local_devices()[0]}"
    )
    code = (
        "import sys, pytest, jax; sys.path.insert(0, 'tests'); import train_helpers as H\n"
        "assert jax.device_count() == 2, jax.devices()\n"
        "H.patch_for_experiments(pytest.MonkeyPatch())\n"
        "import dataclasses; from pathlib import Path; from experiments import sweep; from experiments.running import sweeps; import test_experiments as T\n"
        f"sweep.main(dataclasses.replace(T.sweep_args(Path({str(out)!r})), methods=('a3c',)))\n"
        f"read = sweeps.load_method('a3c', T.sweep_args(Path({str(out)!r})), Path({str(out / 'methods' / 'a3c')!r}))\n"
        f"{on_one_device}\n"
        "from experiments.running import devices; from experiments.running.presets import preset; from foresit_jax.train import make_trainer\n"
        "trainer = make_trainer(preset('tiny', 'a3c+maml')[0])\n"
        "states = jax.vmap(trainer.init)(jax.random.split(jax.random.PRNGKey(0), 2))\n"
        "trainer.run_seeds.lower(devices.shard_seeds(states, devices.seed_mesh(2)), trainer.env_params, 2)\n"
    )  # one method of the two: its numbers do not depend on the others
    env = {**os.environ, "XLA_FLAGS": "--xla_force_host_platform_device_count=2"}
    proc = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    read = sweeps.load_method("a3c", sweep_args(out), out / "methods" / "a3c")
    assert {d for x in jax.tree.leaves(read[2:]) for d in x.sharding.device_set} == {jax.local_devices()[0]}
    one, two = (json.loads((d / "results_per_seed.json").read_text()) for d in (tiny_sweep, out))
    assert list(two) == ["a3c"]
    for a, b in zip(one["a3c"], two["a3c"], strict=True):
        assert (a["seed"], a["selected_update"]) == (b["seed"], b["selected_update"])
        np.testing.assert_allclose(a["training_success_rate"], b["training_success_rate"], atol=1e-6)
        for key in ("selected", "last"):
            for col in ("SR", "SPL", "episodes"):
                assert a[key]["overall"][col] == pytest.approx(b[key]["overall"][col], abs=1e-3)
        assert [v["SR"] for v in a["validation"]] == pytest.approx([v["SR"] for v in b["validation"]])


@pytest.mark.slow
def test_a_killed_sweep_resumes_where_it_stopped_and_ends_with_the_same_numbers(tiny_sweep, tmp_path, capsys):
    out = tmp_path / "killed"
    # 2 chunks per method: a3c finishes, a3c+foresit stops after its first chunk.
    assert sweep.main(dataclasses.replace(sweep_args(out), stop_after_chunks=3)) is None
    assert "continue with --resume" in capsys.readouterr().out
    finished, started = out / "methods" / "a3c", out / "methods" / "a3c+foresit"
    assert (finished / "results.json").exists() and not (started / "results.json").exists()
    assert json.loads((started / "progress.json").read_text())["done"] == 2
    kept = (finished / "results.json").stat().st_mtime_ns
    # (How an arm's run resumes from each state a kill leaves: tests/test_run.py.)
    # A method validated under another selection protocol is not continued under this one.
    progress = json.loads((started / "progress.json").read_text())
    assert progress["selection_protocol"] == selection.PROTOCOL_VERSION
    (started / "progress.json").write_text(json.dumps({**progress, "selection_protocol": 1}))
    line = cli_error(sweep.cli, ["--out", out, "--resume"], capsys)
    assert "a3c+foresit in" in line and "validated under selection protocol 1" in line
    (started / "progress.json").write_text(json.dumps(progress))
    # --resume takes the arguments the sweep was started with, and refuses others.
    assert "drop --seeds 9 (started with 2)" in cli_error(sweep.cli, ["--out", out, "--resume", "--seeds", "9"], capsys)
    sweep.cli(["--out", str(out), "--resume", "--no-progress"])
    assert (finished / "results.json").stat().st_mtime_ns == kept  # a finished method is not run again
    for name in ("results_per_seed.json", "table1.csv", "table1.md"):
        assert (out / name).read_text() == (tiny_sweep / name).read_text(), name


@pytest.mark.slow
def test_a_sweep_copies_the_methods_another_sweep_finished_instead_of_training_them(tiny_sweep, tmp_path, capsys):
    out = tmp_path / "combined"
    # A budget of 0 chunks: nothing may train, both methods must come from tiny_sweep.
    assert sweep.main(dataclasses.replace(sweep_args(out), reuse=(tiny_sweep,), stop_after_chunks=0)) is not None
    assert "a3c+foresit: finished in" in capsys.readouterr().out
    for name in ("results_per_seed.json", "table1.csv", "table1.md"):
        assert (out / name).read_text() == (tiny_sweep / name).read_text(), name
    assert not list((out / "methods").glob(".*"))  # no partial copy left behind
    # Refused in one line: the sweep itself, a folder that is no sweep, another protocol.
    line = cli_error(sweep.cli, ["--out", out, "--overwrite", "--reuse", out], capsys)
    assert "the sweep being written" in line and (out / "table1.md").exists()
    assert "not a sweep folder" in cli_error(sweep.cli, ["--out", tmp_path / "x", "--reuse", tmp_path], capsys)
    argv = ["--preset", "tiny", "--val-episodes-per-room", "5", "--out", tmp_path / "x", "--reuse", tiny_sweep]
    line = cli_error(sweep.cli, argv, capsys)
    assert "another protocol" in line and "--val-episodes-per-room 12 there, 5 here" in line
    # A method selected by an earlier version of experiments.running.selection (no version recorded).
    old = tmp_path / "old"
    shutil.copytree(tiny_sweep, old)
    done = old / "methods" / "a3c" / "results.json"
    done.write_text(json.dumps({k: v for k, v in json.loads(done.read_text()).items() if k != "selection_protocol"}))
    with pytest.raises(errors.UserError, match=r"its a3c was selected by another protocol \(version 1"):
        sweep.main(dataclasses.replace(sweep_args(tmp_path / "x"), reuse=(old,)))
    assert not (tmp_path / "x").exists()
    # A method trained on another platform is combined, and the table says which pair mixes platforms.
    moved = tmp_path / "moved"
    shutil.copytree(tiny_sweep, moved)
    done = moved / "methods" / "a3c+foresit" / "results.json"
    finished = json.loads(done.read_text())
    elsewhere = [{"from_update": 0, "platform": {**numerics.fingerprint(), "jax": "0.0.1"}}]
    for r in finished["results"]:
        assert r["numerics"] == [{"from_update": 0, "platform": numerics.fingerprint()}]
        r["numerics"] = elsewhere
    done.write_text(json.dumps(finished))
    sweep.main(dataclasses.replace(sweep_args(tmp_path / "mixed"), reuse=(moved,), stop_after_chunks=0))
    md = (tmp_path / "mixed" / "table1.md").read_text()
    assert f"- {numerics.describe(elsewhere[0]['platform'])}: a3c+foresit\n" in md
    assert "different platforms (or a run on several): a3c and a3c+foresit." in md
    assert (
        f"Every method was trained on {numerics.describe(numerics.fingerprint())}."
        in (tiny_sweep / "table1.md").read_text()
    )


@pytest.mark.slow
def test_a_sweep_assembles_a_method_from_the_seeds_other_sweeps_finished(tiny_sweep, tmp_path, capsys):
    """Seeds S and S+1 of tiny_sweep and seed S+2 of a one-seed sweep (`--seed S+2
    --seeds 1`) make a three-seed sweep with nothing trained: each seed's results are its
    source's, and the assembled checkpoint holds each seed's own states and selected model
    (what the paper's figures load); a seed no source has makes every seed train."""
    extra = tmp_path / "third"
    sweep.main(dataclasses.replace(sweep_args(extra), methods=("a3c",), seed=SEED + 2, seeds=1))
    capsys.readouterr()
    three = dataclasses.replace(sweep_args(tmp_path / "three"), methods=("a3c",), seeds=3, reuse=(tiny_sweep, extra))
    assert sweep.main(dataclasses.replace(three, stop_after_chunks=0)) is not None  # a budget of 0: nothing trains
    assert f"a3c: assembled (seeds {SEED}-{SEED + 1} from {tiny_sweep}; seeds {SEED + 2} from {extra})" in (
        capsys.readouterr().out
    )
    per_seed = json.loads((three.out / "results_per_seed.json").read_text())["a3c"]
    sources = [json.loads((d / "results_per_seed.json").read_text())["a3c"] for d in (tiny_sweep, extra)]
    assert per_seed == sources[0] + sources[1]
    done = json.loads((three.out / "methods" / "a3c" / "results.json").read_text())
    assert done["curves"] == [r["training_success_rate"] for r in per_seed]
    assert done["assembled_from"] == {
        str(SEED): str(tiny_sweep / "methods" / "a3c"),
        str(SEED + 1): str(tiny_sweep / "methods" / "a3c"),
        str(SEED + 2): str(extra / "methods" / "a3c"),
    }
    md = (three.out / "table1.md").read_text()
    assert (
        f"- a3c: seeds {SEED}-{SEED + 1} from {tiny_sweep / 'methods' / 'a3c'}; "
        f"seeds {SEED + 2} from {extra / 'methods' / 'a3c'}\n"
    ) in md
    assert "combined" not in (tiny_sweep / "table1.md").read_text()
    table = next(csv_rows(three.out / "table1.csv"))
    assert table["seeds"] == "3"
    assert float(table["SR mean"]) == pytest.approx(np.mean([r["selected"]["overall"]["SR"] for r in per_seed]))
    loaded = [sweeps.load_method("a3c", three, d / "methods" / "a3c")[2:] for d in (three.out, tiny_sweep, extra)]
    assert jax.tree.structure(loaded[0]) == jax.tree.structure(loaded[1])
    for got, first, second in zip(*(jax.tree.leaves(x) for x in loaded), strict=True):
        np.testing.assert_array_equal(got, np.concatenate([first, second]))
    # A subset of a source's seeds: seed S+1 alone is taken from tiny_sweep (not copied whole).
    one = dataclasses.replace(
        sweep_args(tmp_path / "one"), methods=("a3c",), seed=SEED + 1, seeds=1, reuse=(tiny_sweep,), stop_after_chunks=0
    )
    assert sweep.main(one) is not None
    assert json.loads((one.out / "results_per_seed.json").read_text())["a3c"] == sources[0][1:]
    # Seed S+3 is in no source: all four seeds would train (a budget of 0 stops it), and it says why.
    four = dataclasses.replace(three, out=tmp_path / "four", seeds=4, stop_after_chunks=0)
    assert sweep.main(four) is None
    out = capsys.readouterr().out
    assert f"a3c: seeds {SEED}-{SEED + 2} are finished in --reuse, but not seeds {SEED + 3}, so all 4 seeds" in out
    assert not (four.out / "methods" / "a3c" / "results.json").exists()
    for d, before in zip((tiny_sweep, extra), sources):  # the sources are only read
        assert json.loads((d / "results_per_seed.json").read_text())["a3c"] == before


def test_the_sweep_command_asks_for_two_host_devices_unless_the_user_chose(monkeypatch):
    from experiments.running import devices

    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_use_thunk_runtime=true")
    devices.split_host_into_devices()
    expected = min(2, os.cpu_count() or 1)
    assert (
        os.environ["XLA_FLAGS"] == f"--xla_cpu_use_thunk_runtime=true --xla_force_host_platform_device_count={expected}"
    )
    monkeypatch.setenv("XLA_FLAGS", "--xla_force_host_platform_device_count=1")
    devices.split_host_into_devices()
    assert os.environ["XLA_FLAGS"] == "--xla_force_host_platform_device_count=1"
    import inspect

    assert "devices.split_host_into_devices()" in inspect.getsource(sweep.console)  # `foresit-sweep`
    assert "console()" in (REPO / "experiments" / "sweep.py").read_text().split("__main__")[-1]  # python -m


def test_seeds_go_to_the_most_devices_that_divide_them():
    from experiments.running import devices

    fake = ["d0", "d1", "d2", "d3"]
    assert [devices.seed_mesh(n, fake).devices.tolist() for n in (5, 6, 8, 3)] == [
        ["d0"],
        ["d0", "d1", "d2"],
        ["d0", "d1", "d2", "d3"],
        ["d0", "d1", "d2"],
    ]


@pytest.mark.slow
def test_cvae_comparison_on_a_run(finished_run, tmp_path, capsys):
    """The C-VAE comparison from a run folder: items of the run's successful episodes, both
    f_w trained, the files written once (never replaced without --overwrite)."""
    from experiments import cvae_compare

    out = tmp_path / "run"
    shutil.copytree(finished_run, out)
    result = cvae_compare.main(cvae_compare.Args(run=out, windows=40, epochs=3))
    assert result["items"] >= cvae_comparison.MIN_ITEMS and result["update"] == 4 and result["latent_size"] == 8
    assert np.isfinite(result["direct"]["loss"]) and np.isfinite(result["cvae_latent"]["loss"])
    assert json.loads((out / "cvae_comparison.json").read_text())["items"] == result["items"]
    assert "C-VAE's latent mean" in (out / "cvae_comparison.md").read_text()
    assert "pass --overwrite" in cli_error(cvae_compare.cli, ["--run", out], capsys)
    assert "raise --windows" in cli_error(cvae_compare.cli, ["--run", out, "--windows", "1", "--overwrite"], capsys)


# ---------------------------------------------------------------------- evaluate CLI
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


# ---------------------------------------------------------------------- the README
README = (REPO / "README.md").read_text()
USAGE = (REPO / "docs" / "usage.md").read_text()  # the README's command line, environment and methods
BLOCKS = re.findall(r"```(\w+)\n(.*?)```", README, flags=re.S)
USAGE_BLOCKS = re.findall(r"```(\w+)\n(.*?)```", USAGE, flags=re.S)
CLI_MODULES = {
    "experiments.train": train_cli,
    "experiments.evaluate": evaluate_cli,
    "experiments.sweep": sweep,
    "experiments.probe": importlib.import_module("experiments.probe"),
    "experiments.failures": importlib.import_module("experiments.failures"),
}
# Benchmarks the README documents: their flags must parse (they run in their own tests or
# take minutes by design).
BENCH_ARGS = {  # commands whose flags are parsed here and which run in their own tests
    "benchmarks.bench_train": lambda: importlib.import_module("benchmarks.bench_train").BenchConfig,
    "benchmarks.bench_learning": lambda: importlib.import_module("benchmarks.bench_learning").BenchLearning,
    "experiments.cvae_compare": lambda: importlib.import_module("experiments.cvae_compare").Args,
    "experiments.paper": lambda: importlib.import_module("experiments.paper").Args,  # tests/test_paper.py runs it
    "experiments.demo": lambda: importlib.import_module("experiments.demo").DemoConfig,
    "benchmarks.bench_env": lambda: importlib.import_module("benchmarks.bench_env").BenchConfig,
    "experiments.compare": lambda: importlib.import_module("experiments.compare").Args,  # tests/test_compare.py
    "experiments.tune": lambda: importlib.import_module("experiments.tune").Args,  # tests/test_tune.py runs it
    "experiments.foresight": lambda: importlib.import_module("experiments.foresight").Args,  # tests/test_foresight.py
    "benchmarks.reference_ppo": lambda: (
        importlib.import_module("benchmarks.reference_ppo").Args
    ),  # tests/test_reference_ppo.py
}


DOCS = {path.name: path.read_text() for path in sorted((REPO / "docs").glob("*.md"))}


def readme_commands(text: str = README) -> list[list[str]]:
    """Every `python -m experiments.X ...` of the bash blocks of `text` (the README's by
    default), as argv lists (a line ending in a backslash continues on the next)."""
    commands = []
    for lang, body in re.findall(r"```(\w+)\n(.*?)```", text, flags=re.S):
        if lang != "bash":
            continue
        for line in body.replace("\\\n", " ").splitlines():
            for part in line.split("&&"):
                if "python -m" not in part:  # `git clone <this repository's URL> ...`: not shell-quoted
                    continue
                words = shlex.split(part, comments=True)
                if words[:2] == ["python", "-m"] and words[2].startswith(("experiments.", "benchmarks.")):
                    commands.append(words[2:])
    return commands


def test_readme_commands_parse():
    """Every documented experiments command (code blocks and inline) names a module that
    exists, and the flags of the train/evaluate/sweep ones are accepted. The README and
    docs/usage.md, where its command line went, show every CLI between them."""
    commands = readme_commands()
    assert {c[0] for c in commands + readme_commands(USAGE)} >= set(CLI_MODULES)
    for module, *argv in commands:
        parser = CLI_MODULES[module].Args if module in CLI_MODULES else BENCH_ARGS[module]()
        args = tyro.cli(parser, args=argv)
        assert dataclasses.is_dataclass(args)
    for module in set(re.findall(r"python -m ((?:experiments|benchmarks)\.\w+)", README)):
        assert importlib.util.find_spec(module) is not None, module
    for link in re.findall(r"\]\(((?!https?:)[^)#]+)\)", README):  # relative links and the picture exist
        assert (REPO / link).exists(), link


def test_the_readmes_first_run_is_the_tiny_one_and_its_snippet_acts():
    """A newcomer's first run takes seconds (`--preset tiny`), then the quick one; the
    library snippet ends with the trained policy in memory (`make_act`, issue 71)."""
    first, second = readme_commands()[:2]
    assert first[0] == second[0] == "experiments.train"
    assert first[first.index("--preset") + 1] == "tiny" and second[second.index("--preset") + 1] == "quick"
    snippet = next(body for lang, body in BLOCKS if lang == "python" and "make_train" in body)
    assert "make_act(" in snippet and "evaluate_policy(" in snippet


@pytest.mark.parametrize("doc", sorted(DOCS))
def test_docs_commands_parse(doc):
    """The commands of docs/ name modules that exist, and their flags are accepted (the
    README's also run, at a tiny size, below)."""
    text = DOCS[doc]
    for module, *argv in readme_commands(text):
        parser = CLI_MODULES[module].Args if module in CLI_MODULES else BENCH_ARGS[module]()
        assert dataclasses.is_dataclass(tyro.cli(parser, args=argv)), (doc, module, argv)
    for module in set(re.findall(r"python -m ((?:experiments|benchmarks)\.\w+)", text)):
        assert importlib.util.find_spec(module) is not None, (doc, module)
    for link in re.findall(r"\]\(((?!https?:)[^)#]+)\)", text):  # relative links lead somewhere
        assert (REPO / "docs" / link).exists(), (doc, link)


def tiny_argv(module: str, argv: list[str], folder: Path) -> list[str]:
    """The same command at a tiny size: preset tiny, run folders under `folder`."""
    out, flag = [], None
    for word in argv:
        if flag == "--preset":
            word = "tiny"
        elif flag in ("--out", "--run"):
            word = str(folder / word)
        out.append(word)
        flag = word if word.startswith("--") else None
    if "progress" in {f.name for f in dataclasses.fields(CLI_MODULES[module].Args)}:
        out.append("--no-progress")
    return out


@pytest.mark.slow
@pytest.mark.timeout(600)
@pytest.mark.parametrize("source", ["README.md", "docs/usage.md"])
def test_readme_commands_run_at_a_tiny_size(tmp_path, capsys, source):
    """The commands of the README and of docs/usage.md (its command line), each page's in
    order in a folder of its own, at a tiny size."""
    commands = readme_commands((REPO / source).read_text())
    assert any(module in CLI_MODULES for module, *_ in commands), source
    for module, *argv in commands:
        if module not in CLI_MODULES:  # benchmarks: parsed above, run by their own tests
            continue
        args = tyro.cli(CLI_MODULES[module].Args, args=tiny_argv(module, argv, tmp_path))
        CLI_MODULES[module].main(args)
    # What each command promises to write.
    runs_written = [p for p in (tmp_path / "runs").iterdir() if rundir.is_run(p)]
    assert runs_written
    for run in runs_written:
        assert (run / "results_test.md").exists() and (run / "learning_curve.png").exists()
    sweeps = [p for p in (tmp_path / "runs").iterdir() if (p / "sweep.json").exists()]
    for folder in sweeps:
        assert (folder / "table1.md").exists() and (folder / "learning_curves.png").exists()
        rows = list(csv_rows(folder / "table1.csv"))
        assert [r["method"] for r in rows] == list(json.loads((folder / "sweep.json").read_text())["methods"])


def csv_rows(path: Path):
    import csv

    with open(path) as f:
        yield from csv.DictReader(f)


@pytest.mark.slow
def test_readme_python_blocks_run_at_a_tiny_size():
    """The Python examples of the README and of docs/usage.md (where its environment block
    went), executed with smaller sizes substituted (bathrooms only, 2 lanes, 1 update, a small
    network): the API calls are the documented ones."""
    python_blocks = [body for lang, body in BLOCKS + USAGE_BLOCKS if lang == "python"]
    assert len(python_blocks) >= 2
    assert any("make_train" in body for lang, body in BLOCKS if lang == "python")  # the README's library snippet
    assert any("envs.make" in body for lang, body in USAGE_BLOCKS if lang == "python")  # usage.md's environment
    small = (
        'num_lanes=2, num_updates=1, room_types=("bathroom",), hidden_size=16, attention_size=16, '
        "value_hidden=16, imagination_layer_sizes=(16, 8, 4, 8, 16, 16)"
    )
    for body in python_blocks:
        code = body.replace('split="train")', 'split="train", room_types=("bathroom",))')
        code = re.sub(r"num_lanes=\d+, num_updates=\d+", small, code)
        assert code != body, "nothing to shrink in this README block: update the substitutions"
        namespace: dict = {}
        exec(compile(code, "README.md", "exec"), namespace)  # noqa: S102
        if "make_train" in body:
            state, metrics = namespace["state"], namespace["metrics"]
            seeds = int(re.search(r"PRNGKey\(0\), (\d+)\)", body).group(1))
            assert np.asarray(state.update).tolist() == [1] * seeds
            assert np.isfinite(np.asarray(metrics["losses/total_loss"])).all()
        if "envs.make" in body:
            assert "obs" in namespace and "state" in namespace
        if "make_act" in body:  # seed 0's policy, its parameters those of seed 0's state
            H.assert_trees_bitwise_equal(namespace["act"].params.params, jax.tree.map(lambda x: x[0], state.params))


def _extending_blocks(evaluating: bool) -> list[str]:
    """docs/extending.md's Python blocks: those that evaluate a policy (tens of seconds of
    compiling) or the others."""
    blocks = re.findall(r"```python\n(.*?)```", DOCS["extending.md"], flags=re.S)
    return [b for b in blocks if ("evaluate_policy" in b) == evaluating]


def test_extending_blocks_run():
    """docs/extending.md's Python blocks run as written (they are small by design)."""
    blocks = _extending_blocks(evaluating=False)
    assert len(blocks) >= 2
    for body in blocks:
        exec(compile(body, "docs/extending.md", "exec"), {})  # noqa: S102
    from foresit_jax import methods

    assert "myint" not in methods.IMAGINATION_VARIANTS  # the example cleans up after itself


@pytest.mark.slow
def test_extending_blocks_that_evaluate_run():
    """docs/extending.md's block that acts and evaluates from a user's own code runs as written."""
    blocks = _extending_blocks(evaluating=True)
    assert len(blocks) == 1
    exec(compile(blocks[0], "docs/extending.md", "exec"), {})  # noqa: S102


def test_console_scripts_are_the_module_programs(monkeypatch, capsys):
    """Each console script of pyproject.toml names a function that runs its module's CLI
    (`foresit-train --help` prints train's usage)."""
    import tomllib

    scripts = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())["project"]["scripts"]
    assert set(scripts) == {
        "foresit-train",
        "foresit-evaluate",
        "foresit-sweep",
        "foresit-tune",
        "foresit-paper",
        "foresit-probe",
        "foresit-failures",
        "foresit-compare",
    }
    for name, target in scripts.items():
        module, function = target.split(":")
        assert module == f"experiments.{name.removeprefix('foresit-')}"
        monkeypatch.setattr(sys, "argv", [name, "--help"])
        monkeypatch.setenv("XLA_FLAGS", os.environ.get("XLA_FLAGS", ""))  # restored after (sweep sets it)
        with pytest.raises(SystemExit) as exc:
            getattr(importlib.import_module(module), function)()
        assert exc.value.code == 0
        # as tyro prints it (tyro 0.9 wraps the description at the terminal's width)
        first_line = importlib.import_module(module).Args.__doc__.split("\n")[0]
        assert " ".join(first_line.split()) in " ".join(capsys.readouterr().out.split())


def test_every_config_field_is_a_flag_of_train_and_sweep():
    """Each Config field but the action count (the environment's) is a flag of train and
    of sweep: its own, or one of the unprefixed Config fields (presets.config_fields)."""
    wanted = {f.name for f in dataclasses.fields(Config)} - {"num_actions", "method"}
    for cli in (train_cli, sweep):
        own = {f.name for f in dataclasses.fields(cli.Args)}
        nested = {f.name for f in dataclasses.fields(cli.Args().config)}
        assert wanted <= own | nested and not own & nested, cli.__name__
    args = tyro.cli(
        train_cli.Args,
        args=[
            "--gamma",
            "0.9",
            "--room-types",
            "bathroom",
            "kitchen",
            "--imagination-layer-sizes",
            "8",
            "128",
            "--maml-first-order",
            "True",
        ],
    )
    config, _ = train_cli.build(args)
    assert (config.gamma, config.room_types, config.maml_first_order) == (0.9, ("bathroom", "kitchen"), True)
    assert config.entropy_coef == presets.preset("quick", "a3c+foresit")[0].entropy_coef  # the rest: the preset's


def test_each_config_field_flag_is_helped_by_its_docstring_on_one_line(capsys):
    """The help of a Config field's flag is the docstring under the field, its source line
    breaks joined (presets._field_docs, read with tyro's docstring_parser): what each
    flag's annotation carries, and what `--help` prints."""
    import typing

    docs = presets._field_docs(Config)
    assert set(docs) == {f.name for f in dataclasses.fields(Config)}
    assert docs["gamma"] == "Discount factor."
    assert all("\n" not in d and "  " not in d for d in docs.values())
    for fields in (presets.TrainConfigFields, presets.SweepConfigFields):
        for name, hint in typing.get_type_hints(fields, include_extras=True).items():
            (arg,) = [m for m in hint.__metadata__ if isinstance(m, type(tyro.conf.arg()))]
            assert arg.help == docs[name], name
    with pytest.raises(SystemExit):
        tyro.cli(train_cli.Args, args=["--help"])
    shown = " ".join(re.sub("[\u2500-\u257f]", " ", capsys.readouterr().out).split())  # box drawing out
    for name in ("priors", "rollout", "gamma", "entropy_coef"):
        assert docs[name] in shown, name


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


@pytest.mark.slow
def test_sweep_config_flags_are_saved_resumed_and_part_of_the_protocol(tmp_path, capsys):
    base = sweep.Args(methods=("a3c",), seeds=1, preset="tiny", seed=SEED, progress=False, **SWEEP_EPISODES)
    first = dataclasses.replace(base, out=tmp_path / "lr", config=presets.SweepConfigFields(learning_rate=3e-4))
    assert sweep.main(dataclasses.replace(first, stop_after_chunks=1)) is None
    line = cli_error(sweep.cli, ["--out", first.out, "--resume", "--learning-rate", "1e-3"], capsys)
    assert "--learning-rate 0.001 (started with 0.0003)" in line
    sweep.cli(["--out", str(first.out), "--resume", "--no-progress"])
    config, *_ = sweeps.load_method("a3c", first, first.out / "methods" / "a3c")
    assert config.learning_rate == 3e-4
    # Reuse takes only the sweeps of the same Config fields.
    other = dataclasses.replace(base, out=tmp_path / "other", reuse=(first.out,))
    line = cli_error(
        sweep.cli,
        [
            "--methods",
            "a3c",
            "--seeds",
            "1",
            "--preset",
            "tiny",
            "--seed",
            SEED,
            "--out",
            other.out,
            "--reuse",
            first.out,
        ],
        capsys,
    )
    assert "run with another protocol" in line and "--config" in line
    # A sweep saved before it had Config fields reads back with none set.
    saved = rundir.read_json(first.out / "sweep.json")
    del saved["config"]
    assert rundir.args_from_saved(sweep.Args, saved).config == presets.SweepConfigFields()


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
