"""`train --track`: TensorBoard and Weights & Biases get the rows the run's CSV files get."""

from __future__ import annotations

import importlib.machinery
import importlib.util
import struct
import sys
import types
from pathlib import Path

import pytest

from experiments import train as train_cli
from experiments import errors
from experiments.running import tracking
from experiments import rundir


# Cheap in-process CLI calls for every test of this module (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("cheap_experiments")


def tiny(out: Path, **kwargs) -> train_cli.Args:
    return train_cli.Args(method="a3c", preset="tiny", seed=2, out=out, progress=False, **kwargs)


def event_scalars(folder: Path) -> dict[str, dict[int, float]]:
    """{tag: {step: value}} of the TensorBoard event files in `folder`, read as the format
    is written (TFRecord: length, its CRC, an Event protobuf, its CRC), not by tensorboardX."""
    from tensorboardX.proto import event_pb2

    scalars: dict[str, dict[int, float]] = {}
    for path in sorted(folder.glob("events.out.tfevents.*")):
        data, at = path.read_bytes(), 0
        while at < len(data):
            (length,) = struct.unpack("<Q", data[at : at + 8])
            event = event_pb2.Event.FromString(data[at + 12 : at + 12 + length])
            at += 12 + length + 4
            for value in event.summary.value:
                scalars.setdefault(value.tag, {})[event.step] = value.simple_value
    return scalars


@pytest.mark.slow
def test_tensorboard_gets_every_metric_and_validation_row_of_the_csv(tmp_path):
    pytest.importorskip("tensorboardX")
    out = tmp_path / "tb"
    train_cli.main(tiny(out, track="tensorboard"))
    scalars = event_scalars(out / "tensorboard")
    rows = rundir.read_rows(out / "metrics")
    for name in ("losses/total_loss", "charts/success_rate", "frames", "losses/explained_variance"):
        assert scalars[name] == pytest.approx({r["update"]: r[name] for r in rows}, rel=1e-6), name
    (validation,) = rundir.read_json(out / "progress.json")["history"]
    assert scalars["validation/SR"] == pytest.approx({r["update"]: r["SR"] for r in validation})


@pytest.mark.slow
def test_wandb_gets_the_same_rows_under_one_run_id_across_a_resume(tmp_path, monkeypatch):
    calls = []

    class Run:
        def log(self, row, step):
            calls.append(("log", step, row))

        def finish(self):
            calls.append(("finish",))

    fake = types.ModuleType("wandb")
    fake.__spec__ = importlib.machinery.ModuleSpec("wandb", None)
    fake.init = lambda **kw: calls.append(("init", kw)) or Run()
    monkeypatch.setitem(sys.modules, "wandb", fake)
    monkeypatch.delenv("WANDB_API_KEY", raising=False)
    monkeypatch.delenv("WANDB_MODE", raising=False)
    out = tmp_path / "wb"
    train_cli.main(tiny(out, track="wandb", stop_after_chunks=1))
    train_cli.main(train_cli.Args(out=out, resume=True, progress=False, track="wandb"))
    inits = [c[1] for c in calls if c[0] == "init"]
    assert len(inits) == 2 and inits[0]["id"] == inits[1]["id"] and inits[0]["resume"] == "allow"
    assert all(kw["mode"] == "offline" and kw["dir"] == str(out / "wandb") for kw in inits)
    logged = {step: row for kind, *rest in calls if kind == "log" for step, row in [rest] if "losses/total_loss" in row}
    assert sorted(logged) == [r["update"] for r in rundir.read_rows(out / "metrics")]
    assert {r["update"]: r["losses/total_loss"] for r in rundir.read_rows(out / "metrics")} == pytest.approx(
        {step: row["losses/total_loss"] for step, row in logged.items()}
    )


def test_an_unknown_or_missing_tracker_is_one_line_before_training(tmp_path, monkeypatch):
    with pytest.raises(errors.UserError, match="must be one of"):
        tracking.check("mlflow")
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "wandb" else real(name, *a))
    monkeypatch.delitem(sys.modules, "wandb", raising=False)
    with pytest.raises(errors.UserError, match=r"pip install 'foresit_jax\[track\]'"):
        train_cli.main(tiny(tmp_path / "none", track="wandb"))
    assert not (tmp_path / "none").exists()
