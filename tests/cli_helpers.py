"""Helpers shared by the tests of the experiments programs (tests/experiments/): a tiny run's
and a tiny sweep's arguments, reads of a run folder, and the check of a one-line error.
The fixtures that train them once a session are tests/experiments/conftest.py's."""

import json
from pathlib import Path

import jax
import pytest

import train_helpers as H
from experiments import rundir
from experiments import sweep
from experiments import train as train_cli
from experiments.running import checkpoint
from experiments.running.run import initial_states
from foresit_jax.config import Config

SEED = 3


def tiny_args(out: Path, **kwargs) -> train_cli.Args:
    return train_cli.Args(method="a3c+foresit", preset="tiny", seed=SEED, out=out, progress=False, **kwargs)


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


def cli_error(cli, argv, capsys, code: int = 2) -> str:
    """Run a CLI that must fail: exit status `code` and exactly one line on stderr, no traceback."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        cli([str(a) for a in argv])
    err = capsys.readouterr().err
    assert exc.value.code == code, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err
    return lines[0]


def strict_json(text: str):
    """json.loads that refuses NaN/Infinity (not JSON, though Python writes them by default)."""

    def refuse(token):
        raise ValueError(f"non-strict JSON token {token}")

    return json.loads(text, parse_constant=refuse)


SWEEP_EPISODES = dict(val_episodes_per_room=12, test_episodes_per_room=24)  # enough that other keys give other numbers


def sweep_args(out: Path) -> sweep.Args:
    return sweep.Args(
        methods=("a3c", "a3c+foresit"), seeds=2, preset="tiny", seed=SEED, out=out, progress=False, **SWEEP_EPISODES
    )


def csv_rows(path: Path):
    import csv

    with open(path) as f:
        yield from csv.DictReader(f)
