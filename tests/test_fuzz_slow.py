"""The fuzz's slow half (issue 71; the table is tests/test_fuzz.py): damage to a trained
run's checkpoints and files, which needs a run trained here, and refusals through a real
subprocess (`python -m experiments.<program>`), as a user meets them.

Each case asserts what test_fuzz asserts: the exit status, one `error:` line (or tyro's
framed message), no traceback, and the folder as it was.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import train_helpers as H
from experiments import train as train_cli
from test_fuzz import FLAGS, check_refused, fill, listing, places

pytestmark = [pytest.mark.slow, pytest.mark.usefixtures("cheap_experiments")]
REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def trained(tmp_path_factory, cheap_experiments):
    """A finished tiny run (4 updates, 2 checkpoints kept)."""
    out = tmp_path_factory.mktemp("fuzz") / "run"
    train_cli.main(train_cli.Args(method="a3c+foresit", preset="tiny", seed=0, out=out, progress=False))
    return out


def no_checkpoints(run: Path) -> None:
    shutil.rmtree(run / "checkpoints")


def every_checkpoint(how: str):
    def damage(run: Path) -> None:
        for step in (p for p in (run / "checkpoints").iterdir() if p.name.isdigit()):
            H.corrupt_checkpoint(step, how)

    return damage


def truncated(name: str):
    def damage(run: Path) -> None:
        raw = (run / name).read_bytes()
        (run / name).write_bytes(raw[: len(raw) // 2])

    return damage


# (what is done to the run, the program that reads it, the words its one line must hold)
CASES = [
    ("checkpoints deleted", no_checkpoints, ["evaluate", "--run", "{run}", "--split", "val"], "checkpoint"),
    ("checkpoints deleted", no_checkpoints, ["failures", "--run", "{run}"], "checkpoint"),
    (
        "every checkpoint flipped",
        every_checkpoint("flipped"),
        ["evaluate", "--run", "{run}", "--split", "val"],
        "corrupt",
    ),
    (
        "every checkpoint truncated",
        every_checkpoint("truncated"),
        ["evaluate", "--run", "{run}", "--split", "val"],
        "corrupt",
    ),
    (
        "progress.json truncated",
        truncated("progress.json"),
        ["evaluate", "--run", "{run}", "--split", "val"],
        "progress.json",
    ),
    ("results.json truncated", truncated("results.json"), ["train", "--resume", "--out", "{run}"], "results.json"),
    ("run.json truncated", truncated("run.json"), ["evaluate", "--run", "{run}", "--split", "val"], "run.json"),
]


@pytest.mark.parametrize("label,damage,argv,words", CASES, ids=[f"{c[0]} {c[2][0]}" for c in CASES])
def test_damage_to_a_trained_run_is_named_in_one_line(label, damage, argv, words, trained, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(trained, run)
    (run / ".lock").unlink(missing_ok=True)  # the copy's, made by the fixture's claim
    damage(run)
    err = check_refused(argv[0], [a.replace("{run}", str(run)) for a in argv[1:]], 2, tmp_path, capsys)
    assert words in err, err


# A few of the table's cases, each through its own interpreter, as a user runs them.
PICKED = (
    ["--seed", "-1"],
    ["--num-lanes", str(10**9)],
    ["--room-types", "attic"],
    ["--seeds", str(10**6)],
    ["--run", "{missing}"],
    ["--learning-rate", "abc"],
    ["--out", "{file}"],
    ["--out", "{missing}", "--resume"],
)
SUBPROCESS = [next(c for c in FLAGS if c[1] == argv) for argv in PICKED]  # the first program each is given to


@pytest.mark.parametrize("program,argv,status", SUBPROCESS, ids=[f"{p} {' '.join(a)}"[:50] for p, a, _ in SUBPROCESS])
def test_a_refusal_through_a_subprocess_is_one_line(program, argv, status, tmp_path):
    where = places(tmp_path)
    try:
        given_out = "--out" in argv or program not in ("train", "sweep", "tune", "paper", "foresight")
        preset = ["--preset", "tiny"] if program in ("train", "sweep", "tune", "paper") else []
        before = listing(tmp_path)
        env = {**os.environ, "COLUMNS": "80"}
        done = subprocess.run(
            [sys.executable, "-m", f"experiments.{program}", *fill([*argv, *preset], where, given_out)],
            capture_output=True,
            text=True,
            cwd=REPO,
            env=env,
            timeout=120,
        )
        shown = f"{program} {argv}: {done.returncode}\n{done.stderr}"
        assert done.returncode == status, shown
        assert "Traceback" not in done.stderr, shown
        lines = done.stderr.strip().splitlines()
        assert "For full helptext" in done.stderr or (lines and lines[-1].startswith("error:")), shown
        assert [x for x in lines if x.startswith("error:")] in ([], [lines[-1]]), shown
        assert listing(tmp_path) == before, shown
    finally:
        (tmp_path / "read-only").chmod(0o755)
