"""experiments.rundir, the run-folder format: strict JSON (NaN as null), CSV rows, a sweep
folder's reads, and a folder it did not write is never deleted."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from cli_helpers import csv_rows, strict_json
from experiments import errors
from experiments import rundir
from experiments.errors import RunNotFound


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
