"""`experiments.sweep --resume --num-updates N` extends a sweep: every method trains on
from its checkpoint to N updates and ends where a sweep of N updates from the start ends
(nothing in training depends on the total), its earlier results kept beside; what cannot
be extended is refused in one line before anything changes."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from experiments import sweep
from experiments import errors
from experiments.running import selection, sweeps
from experiments import rundir

# Cheap in-process CLI calls (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("cheap_experiments")


def started(folder: Path, **kwargs) -> sweeps.Sweep:
    """A sweep folder as `run` starts it (sweep.json), without training anything."""
    spec = sweeps.Sweep(methods=("a3c",), seeds=2, preset="tiny", out=folder, **kwargs)
    folder.mkdir(parents=True)
    rundir.write_started_args(folder / "sweep.json", spec, ())
    return spec


def finished_method(folder: Path, method: str, updates: int, progress: bool = True, protocol=None) -> Path:
    """A method folder that reads as finished after `updates` (with or without progress.json,
    with its last checkpoint's folder), validated under `protocol` (this code's by default)."""
    path = folder / "methods" / method
    (path / "checkpoints" / str(updates)).mkdir(parents=True)
    protocol = selection.PROTOCOL_VERSION if protocol is None else protocol
    rundir.write_json(
        path / "results.json", {"updates": updates, "results": [], "curves": [], "selection_protocol": protocol}
    )
    if progress:
        rundir.write_json(path / "progress.json", {"done": updates})
    return path


def listing(folder: Path) -> dict:
    """Every file under `folder` (but the lock) with its bytes."""
    return {
        str(p.relative_to(folder)): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.name != rundir.LOCK_FILE
    }


def test_a_sweep_is_never_shortened(tmp_path):
    spec = started(tmp_path / "s", num_updates=6)
    with pytest.raises(errors.UserError, match="--num-updates 4 would shorten .* \\(6 updates\\)"):
        sweeps.extend(spec.out, 4)
    assert sweeps.extend(spec.out, 6) == spec  # the same count: nothing to do


@pytest.mark.parametrize(
    "why, make, says",
    [
        ("assembled", dict(progress=False), "was assembled from other sweeps' seeds"),
        ("another protocol", dict(protocol=1), "validated under selection protocol 1"),
        ("no checkpoint", dict(), "keeps no checkpoint of its update 6"),
    ],
)
def test_what_cannot_continue_is_refused_before_anything_moves(tmp_path, why, make, says):
    spec = started(tmp_path / "s", num_updates=6)
    method = finished_method(spec.out, "a3c", 6, **make)
    if why == "no checkpoint":
        (method / "checkpoints" / "6").rmdir()
    (spec.out / "table1.md").write_text("the 6-update report")
    before = listing(spec.out)
    with pytest.raises(errors.UserError, match=says):
        sweeps.extend(spec.out, 12)
    assert listing(spec.out) == before


def test_a_flag_that_contradicts_the_sweep_is_refused_before_it_is_extended(tmp_path, capsys):
    spec = started(tmp_path / "s", num_updates=6)
    finished_method(spec.out, "a3c", 6)
    (spec.out / "table1.md").write_text("the 6-update report")
    before = listing(spec.out)
    with pytest.raises(SystemExit):
        sweep.cli(["--out", str(spec.out), "--resume", "--num-updates", "12", "--seeds", "7", "--no-progress"])
    assert "--seeds 7 (started with 2)" in capsys.readouterr().err
    assert listing(spec.out) == before


def test_an_extension_killed_while_moving_the_report_is_repaired_by_the_same_call(tmp_path):
    spec = started(tmp_path / "s", num_updates=6)
    finished_method(spec.out, "a3c", 6)
    (spec.out / "report_6_updates").mkdir()
    (spec.out / "report_6_updates" / "table1.md").write_text("moved before the kill")
    (spec.out / "table1.csv").write_text("left behind")
    sweeps.extend(spec.out, 12)
    assert listing(spec.out / "report_6_updates") == {
        "table1.md": b"moved before the kill",
        "table1.csv": b"left behind",
    }
    assert sweeps.saved(spec.out).num_updates == 12


def test_an_extension_off_the_chunk_grid_says_it_will_not_match_a_run_from_the_start(tmp_path, capsys):
    spec = started(tmp_path / "s", num_updates=5)  # tiny's chunk is 2 updates
    sweeps.extend(spec.out, 8)
    assert "not a whole number of chunks" in capsys.readouterr().err
    spec = started(tmp_path / "t", num_updates=4)
    sweeps.extend(spec.out, 8)
    assert "chunks" not in capsys.readouterr().err


def test_an_extension_keeps_the_report_records_itself_and_drops_the_spent_reuse(tmp_path):
    source = started(tmp_path / "source", num_updates=6)
    spec = started(tmp_path / "s", num_updates=6, reuse=(source.out,))
    method = finished_method(spec.out, "a3c", 6)
    (spec.out / "table1.md").write_text("the 6-update report")
    extended = sweeps.extend(spec.out, 12)
    assert extended == dataclasses.replace(spec, num_updates=12, reuse=())
    assert sweeps.saved(spec.out) == extended
    record = json.loads((spec.out / "sweep.json").read_text())
    assert record["extensions"] == [{"from_updates": 6, "to_updates": 12, "reuse": [str(source.out)]}]
    assert (spec.out / "report_6_updates" / "table1.md").read_text() == "the 6-update report"
    assert not (spec.out / "table1.md").exists()
    # No finished method reads as one of 12 updates (compare, --reuse): its results are set aside.
    assert (method / "results_6_updates.json").is_file() and not (method / "results.json").exists()
    # A second extension records both, and a report of the same count already kept is refused.
    (spec.out / "table1.md").write_text("the 12-update report")
    sweeps.extend(spec.out, 20)
    assert [e["to_updates"] for e in json.loads((spec.out / "sweep.json").read_text())["extensions"]] == [12, 20]
    spec_again = started(tmp_path / "t", num_updates=6)
    (spec_again.out / "report_6_updates").mkdir()
    (spec_again.out / "report_6_updates" / "table1.md").write_text("kept earlier")
    (spec_again.out / "table1.md").write_text("another report")
    with pytest.raises(errors.UserError, match="already holds table1.md in report_6_updates/"):
        sweeps.extend(spec_again.out, 12)
    assert (spec_again.out / "report_6_updates" / "table1.md").read_text() == "kept earlier"


def test_set_aside_never_overwrites_kept_results(tmp_path):
    method = finished_method(tmp_path, "a3c", 6)
    (method / "results_6_updates.json").write_text("kept earlier")
    with pytest.raises(errors.UserError, match="both results.json and results_6_updates.json"):
        sweeps.set_aside(method, 6)
    assert (method / "results_6_updates.json").read_text() == "kept earlier"


@pytest.mark.slow
def test_an_extended_sweep_ends_as_the_sweep_of_that_many_updates_from_the_start(tmp_path, capsys):
    args = sweep.Args(
        methods=("a3c", "a3c+critic"),
        seeds=2,
        preset="tiny",
        num_updates=4,
        progress=False,
        val_episodes_per_room=4,
        test_episodes_per_room=4,
    )
    short, whole = tmp_path / "short", tmp_path / "whole"
    sweep.main(dataclasses.replace(args, out=short))
    earlier = {m: (short / "methods" / m / "results.json").read_text() for m in args.methods}
    table = (short / "table1.md").read_text()
    sweep.main(dataclasses.replace(args, out=whole, num_updates=8))
    capsys.readouterr()
    sweep.cli(["--out", str(short), "--resume", "--num-updates", "8", "--no-progress"])
    out = capsys.readouterr().out
    assert f"extending {short} from 4 to 8 updates" in out
    for name in ("results_per_seed.json", "table1.csv"):
        assert (short / name).read_text() == (whole / name).read_text(), name
    for m in args.methods:
        assert (short / "methods" / m / "results_4_updates.json").read_text() == earlier[m]
        assert f"{m}: its 4-update results are kept as results_4_updates.json" in out
    assert (short / "report_4_updates" / "table1.md").read_text() == table
    # Resumed again: finished at 8, nothing trains, nothing moves.
    sweep.cli(["--out", str(short), "--resume", "--no-progress"])
    assert sorted(p.name for p in (short / "methods" / "a3c").glob("results*.json")) == [
        "results.json",
        "results_4_updates.json",
    ]
