"""The fuzz's slow half (issue 71; the table is tests/experiments/test_fuzz.py): damage to a trained
run's checkpoints and files, which needs a run trained here, and refusals through a real
subprocess (`python -m experiments.<program>`), as a user meets them.

Each case asserts what test_fuzz asserts: the exit status, one `error:` line (or tyro's
framed message), no traceback, and the folder as it was.

Issue 80's classes (test_fuzz.py's strategies and bodies) at many more cases than the
default tier runs, a few generated cases of each through a subprocess, and policies
right in every respect (but varied: integer dtypes, a list for the pair, carries of
several trees) played to the end by `evaluate_policy`.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import jax.numpy as jnp
from hypothesis import strategies as st

import test_fuzz as F
import train_helpers as H
from experiments import train as train_cli
from test_fuzz import FLAGS, check_refused, fill, listing, places

pytestmark = [pytest.mark.slow, pytest.mark.usefixtures("cheap_experiments")]
REPO = Path(__file__).resolve().parents[2]


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


def refused_by_subprocess(program: str, argv: list[str], status: int, root: Path) -> str:
    """`python -m experiments.<program> argv` in its own interpreter: its status, one
    `error:` line (or tyro's framed message), no traceback, `root` as it was. Returns stderr."""
    before = listing(root)
    env = {**os.environ, "COLUMNS": "80"}
    done = subprocess.run(
        [sys.executable, "-m", f"experiments.{program}", *argv],
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
    assert listing(root) == before, shown
    return done.stderr


@pytest.mark.parametrize("program,argv,status", SUBPROCESS, ids=[f"{p} {' '.join(a)}"[:50] for p, a, _ in SUBPROCESS])
def test_a_refusal_through_a_subprocess_is_one_line(program, argv, status, tmp_path):
    where = places(tmp_path)
    try:
        given_out = "--out" in argv or program not in ("train", "sweep", "tune", "paper", "foresight")
        preset = ["--preset", "tiny"] if program in ("train", "sweep", "tune", "paper") else []
        refused_by_subprocess(program, fill([*argv, *preset], where, given_out), status, tmp_path)
    finally:
        (tmp_path / "read-only").chmod(0o755)


# ---------------------------------------------------------------------- issue 80's classes, at length
def test_arms_and_flags_at_length(tmp_path_factory, capsys):
    F.passes(F.arm_cases(), F.check_arm_and_flag, 400)
    F.passes(F.arm_cases(agree=True), F.check_arm_and_flag, 200)
    F.passes(F.maml_cases(), F.check_maml_requirement, 200)
    cli = lambda case: F.check_cli_arm(case, tmp_path_factory, capsys)  # noqa: E731
    F.passes(F.CLI_CONFLICTS, cli, 40)
    F.passes(F.CLI_MAML, cli, 20)


def test_paths_the_os_refuses_at_length(tmp_path_factory, capsys):
    check = lambda case: F.check_path_case(case, tmp_path_factory, capsys)  # noqa: E731
    F.passes(F.path_cases(), check, 80)
    F.passes(F.LONG_ARMS, check, 10)


def test_config_types_at_length(tmp_path_factory, capsys):
    F.passes(F.wrong_typed(), F.check_wrong_type_refused, 600)
    F.passes(F.acceptably_typed(), F.check_acceptable_type_taken, 400)
    F.passes(F.WRONG_IN_RUN_JSON, lambda case: F.check_wrong_type_in_run_json(case, tmp_path_factory, capsys), 30)


def test_the_api_boundary_at_length(tmp_path):
    F.passes(F.bad_policies(), F.check_bad_policy_refused, 80)
    F.passes(F.STATE_CASES, F.check_damaged_state_refused, 40)
    (tmp_path / "run.json").write_text("{}")
    F.passes(F.SEED_CASES, lambda case: F.check_bad_seed_refused(case, tmp_path), 60)


def subprocess_case(case, factory) -> None:
    """A generated case of the arm or path class, refused by its program in its own interpreter."""
    root = factory.mktemp("case")
    if isinstance(case, F.PathCase):
        parent = root.joinpath(*case.above)
        parent.mkdir(parents=True, exist_ok=True)
        for name, target in case.links:
            (parent / name).symlink_to(target)
        path = parent.joinpath(case.bad, *case.below)
        err = refused_by_subprocess(
            case.program, [*F.PROGRAM_ARGS.get(case.program, []), *case.flag.split(), str(path)], 2, root
        )
        assert any(w in err for w in F.PATH_WORDS[case.kind]), err
    else:
        program, arm_case = case
        argv, words = F.cli_arm_case(program, arm_case, root)
        err = refused_by_subprocess(program, argv, 2, root)
        assert all(w in err for w in words), (words, err)


def test_generated_cases_through_a_subprocess(tmp_path_factory):
    """Two generated cases of each class a program refuses (an arm against a flag, a
    method's needs broken, a path the OS refuses), each in its own interpreter."""
    run = lambda case: subprocess_case(case, tmp_path_factory)  # noqa: E731
    for strategy in (F.CLI_CONFLICTS, F.CLI_MAML, F.path_cases()):
        F.passes(strategy, run, 2)


@st.composite
def good_policies(draw):
    """A policy right in every respect, varied where it may vary: episodes per room, the
    actions' integer dtype, a list or a tuple for the pair, the carry's tree."""
    lanes = draw(st.integers(1, 3))
    dtype = draw(st.sampled_from(("int32", "int8", "uint8", "int16")))
    carry = draw(st.sampled_from(tuple(F.INITIAL_CARRIES)))
    pair = draw(st.sampled_from((tuple, list)))
    action = draw(st.integers(0, 5))
    return lanes, dtype, carry, pair, action


def check_good_policy_played(case) -> None:
    lanes, dtype, carry, pair, action = case
    policy = lambda params, c, obs, first, key: pair((jnp.full((lanes,), action, dtype), c))  # noqa: E731
    results = F.evaluate_module.evaluate_policy(
        policy, None, F.INITIAL_CARRIES[carry], F.API_CONFIG, "test", episodes_per_room=lanes
    )
    assert results["overall"]["episodes"] == lanes and 0 <= results["overall"]["SR"] <= 100, results


def test_a_policy_right_in_every_respect_is_played():
    """The check refuses nothing it should take: two generated right policies play their
    episodes to the end (a compile of a whole episode each, about 5-9 s on 2 cores)."""
    F.passes(good_policies(), check_good_policy_played, 2)
