"""The project's own fuzz of bad input (issue 71): a table of flags, arm strings, damaged
run folders and unusable outputs, given to every program, and a hypothesis strategy over
flag values and folder damage.

Each case asserts what a user sees: the exit status; on stderr either one `error:` line or
tyro's framed message (for a value that does not parse), never a traceback; and the tree
under the test's folder exactly as it was (no run.json, no .lock, no empty checkpoints/).

The programs are called in-process (`cli(argv)`, SystemExit caught, stderr read with
capsys): every case here is refused before anything trains or compiles. Cases that need a
trained run (flipped checkpoint bytes, deleted checkpoints) and the same refusals through
a subprocess are in the slow tier (`test_fuzz_slow.py`).
"""

from __future__ import annotations

import hashlib
import importlib
import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from experiments.running import presets, sweeps
from experiments import rundir
from experiments.running.run import Run

PROGRAMS = ("train", "sweep", "tune", "paper", "evaluate", "compare", "probe", "failures", "cvae_compare", "foresight")
TOO_BIG = str(2**70)

# (program, argv, exit status). In argv: {out} a path not yet made; {file} a plain file;
# {ro} a read-only folder's child (root writes there: skipped); {under_file} a path under a
# plain file; {uni} a new path with spaces and unicode; {run} a
# started one-seed run (run.json only); {sweep} a started sweep (sweep.json only);
# {missing} a path that is not there.
FLAGS = [
    # train: numbers out of range, values that do not name anything, exclusive flags
    ("train", ["--seed", "-1"], 2),
    ("train", ["--seed", TOO_BIG], 2),
    ("train", ["--seed", "1.5"], 2),
    ("train", ["--num-lanes", "0"], 2),
    ("train", ["--num-lanes", "-4"], 2),
    ("train", ["--num-lanes", str(10**9)], 2),
    ("train", ["--num-updates", "0"], 2),
    ("train", ["--num-updates", "-5"], 2),
    ("train", ["--num-updates", str(10**20)], 2),
    ("train", ["--num-steps", "0"], 2),
    ("train", ["--hidden-size", "0"], 2),
    ("train", ["--buffer-size", "0"], 2),
    ("train", ["--learning-rate", "abc"], 2),
    ("train", ["--learning-rate", "-1"], 2),
    ("train", ["--learning-rate", "nan"], 2),
    ("train", ["--gamma", "1.5"], 2),
    ("train", ["--room-types", "attic"], 2),
    ("train", ["--room-types", "kitchen", "kitchen"], 2),
    ("train", ["--layout", "castle"], 2),
    ("train", ["--perception-range", "-1"], 2),
    ("train", ["--setup", "xyz"], 2),
    ("train", ["--preset", "huge"], 2),
    ("train", ["--method", "a3c+nothing"], 2),
    ("train", ["--method", ""], 2),
    ("train", ["--method", "a3c@"], 2),
    ("train", ["--method", "a3c@lr=3"], 2),
    ("train", ["--method", "a3c@learning_rate=abc"], 2),
    ("train", ["--method", "a3c@learning_rate"], 2),
    ("train", ["--method", "a3c@priors=true"], 2),
    ("train", ["--method", "a3c+org"], 2),  # the object graph needs --setup org
    ("train", ["--chunk-updates", "0"], 2),
    ("train", ["--test-episodes-per-room", "0"], 2),
    ("train", ["--val-episodes-per-room", "-1"], 2),
    ("train", ["--track", "bogus"], 2),
    ("train", ["--resume", "--overwrite"], 2),
    ("train", ["--unknown-flag", "1"], 2),
    # sweep: seeds, arms, reuse
    ("sweep", ["--seeds", "0"], 2),
    ("sweep", ["--seeds", "-1"], 2),
    ("sweep", ["--seeds", str(10**6)], 2),
    ("sweep", ["--seed", str(2**63 - 1), "--seeds", "2"], 2),
    ("sweep", ["--methods"], 2),
    ("sweep", ["--methods", "a3c", "a3c"], 2),
    ("sweep", ["--methods", "a3c", "bogus"], 2),
    ("sweep", ["--methods", "a3c@learning_rate=1e-3,learning_rate=x"], 2),
    ("sweep", ["--reuse", "{missing}"], 2),
    ("sweep", ["--reuse", "{file}"], 2),
    ("sweep", ["--num-lanes", str(10**9)], 2),
    ("sweep", ["--num-updates", str(10**8)], 2),
    ("sweep", ["--val-episodes-per-room", "0"], 2),
    # tune and paper
    ("tune", ["--grid", "learning_rate"], 2),
    ("tune", ["--grid", "learning_rate="], 2),
    ("tune", ["--grid", "nothing=1,2"], 2),
    ("tune", ["--grid", "learning_rate=1e-3,1e-3"], 2),
    ("tune", ["--seeds", "0", "--grid", "learning_rate=1e-3,3e-4"], 2),
    ("tune", ["--seeds", str(10**6), "--grid", "learning_rate=1e-3,3e-4"], 2),
    ("tune", ["--methods", "a3c", "a3c", "--grid", "learning_rate=1e-3,3e-4"], 2),
    ("paper", ["--exclude", "bogus"], 2),
    ("paper", ["--arms", "bogus@learning_rate=1"], 2),
    ("paper", ["--seeds", "0"], 2),
    ("paper", ["--seeds", str(10**6)], 2),
    ("paper", ["--seed", TOO_BIG], 2),
    # the readers: a run that is not there, a file, a run with nothing trained
    ("evaluate", ["--run", "{missing}"], 2),
    ("evaluate", ["--run", "{file}"], 2),
    ("evaluate", ["--run", "{run}", "--split", "train"], 2),
    ("evaluate", ["--run", "{run}"], 2),  # run.json, no checkpoint
    ("evaluate", ["--run", "{uni}"], 2),
    ("compare", ["--run", "{missing}"], 2),
    ("compare", ["--run", "{run}"], 2),
    ("compare", ["--run", "{sweep}", "--pairs", "a3c:bogus"], 2),
    ("probe", ["--run", "{missing}"], 2),
    ("probe", ["--run", "{run}"], 2),
    ("failures", ["--run", "{missing}"], 2),
    ("failures", ["--run", "{run}", "--split", "nowhere"], 2),
    ("cvae_compare", ["--run", "{missing}"], 2),
    ("cvae_compare", ["--run", "{run}"], 2),
    ("foresight", ["--resets", "0"], 2),
    ("foresight", ["--setup", "xyz"], 2),
    ("foresight", ["--layout", "castle"], 2),
    ("foresight", ["--perception-range", "-1"], 2),
    # outputs that cannot be written, and --resume of what is not a run
    ("train", ["--out", "{file}"], 2),
    ("train", ["--out", "{ro}"], 2),
    ("train", ["--out", "{under_file}"], 2),
    ("train", ["--out", "{missing}", "--resume"], 2),
    ("train", ["--out", "{uni}", "--resume"], 2),
    ("train", ["--out", "{sweep}", "--resume"], 2),
    ("train", ["--out", "{run}", "--resume", "--seed", "5"], 2),
    ("train", ["--out", "{run}"], 2),  # already exists
    ("sweep", ["--out", "{file}"], 2),
    ("sweep", ["--out", "{ro}"], 2),
    ("sweep", ["--out", "{under_file}"], 2),
    ("sweep", ["--out", "{run}"], 2),
    ("sweep", ["--out", "{missing}", "--resume"], 2),
    ("sweep", ["--out", "{sweep}", "--resume", "--seeds", "3"], 2),
    ("tune", ["--out", "{file}", "--grid", "learning_rate=1e-3,3e-4"], 2),
    ("paper", ["--out", "{file}"], 2),
    ("foresight", ["--out", "{file}"], 2),
    ("foresight", ["--seed", TOO_BIG], 2),
    ("foresight", ["--out", "{run}"], 2),  # holds foresight.md
]

# The files a damaged folder can hold, and the program (argv) that reads each.
DAMAGE = {"empty": b"", "truncated": b'{"format": 3, "arm": "a3', "binary": bytes(range(256)), "a list": b"[1, 2]"}
READERS = {
    "run.json": [
        ["train", "--resume", "--out", "{run}"],
        ["evaluate", "--run", "{run}"],
        ["probe", "--run", "{run}"],
        ["cvae_compare", "--run", "{run}"],
    ],
    "progress.json": [["train", "--resume", "--out", "{run}"]],
    "results.json": [["train", "--resume", "--out", "{run}"]],
    "sweep.json": [["sweep", "--resume", "--out", "{sweep}"], ["compare", "--run", "{sweep}"]],
}
DAMAGED = [(name, damage, argv) for name, argvs in READERS.items() for argv in argvs for damage in DAMAGE]


# ---------------------------------------------------------------------- the folders
def started_run(folder: Path, exist_ok: bool = False) -> Path:
    """A run folder as train leaves it before its first chunk: run.json (and what is there)."""
    config, schedule = presets.preset("tiny", "a3c+foresit")
    folder.mkdir(parents=True, exist_ok=exist_ok)
    rundir.write_run_info(folder, Run(folder, config, schedule, (0,), "a3c+foresit", "tiny").info())
    return folder


def started_sweep(folder: Path) -> Path:
    """A sweep folder as sweep leaves it before its first chunk: sweep.json only."""
    folder.mkdir(parents=True)
    rundir.write_started_args(
        folder / "sweep.json", sweeps.Sweep(methods=("a3c", "a3c+foresit"), preset="tiny", seeds=2, out=folder), ()
    )
    return folder


def places(root: Path) -> dict[str, Path]:
    """The placeholders of the table, made under `root`."""
    ro = root / "read-only"
    ro.mkdir()
    (root / "plain file").write_text("not a folder\n")
    (root / "run" / "foresight.md").parent.mkdir()
    (root / "run" / "foresight.md").write_text("a report the user keeps\n")
    places = {
        "out": root / "out",
        "file": root / "plain file",
        "ro": ro / "out",
        "uni": root / "ein Lauf é ü 跑",
        "under_file": root / "plain file" / "out",
        "run": started_run(root / "run", exist_ok=True),
        "sweep": started_sweep(root / "sweep"),
        "missing": root / "no such",
    }
    ro.chmod(0o555)
    return places


def listing(root: Path) -> dict[str, str]:
    """Every path under `root` with a digest of its bytes (folders: 'dir'), and its mode."""
    out = {}
    for path in sorted(root.rglob("*")):
        kind = "dir" if path.is_dir() else hashlib.sha256(path.read_bytes()).hexdigest()
        out[str(path.relative_to(root))] = f"{kind} {oct(path.stat().st_mode & 0o777)}"
    return out


def call(program: str, argv: list[str], capsys) -> tuple[int, str]:
    """`python -m experiments.<program> argv`, in-process: (exit status, stderr)."""
    cli = importlib.import_module(f"experiments.{program}").cli
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        cli(argv)
    return exc.value.code, capsys.readouterr().err


def check_refused(program: str, argv: list[str], status: int, root: Path, capsys) -> str:
    """Run the case; assert its status, one `error:` line or tyro's framed message, no
    traceback, and the tree under `root` as it was. Returns stderr."""
    before = listing(root)
    code, err = call(program, argv, capsys)
    shown = f"{program} {' '.join(argv)} -> {code}:\n{err}"
    assert code == status, shown
    assert "Traceback" not in err, shown
    lines = err.strip().splitlines()
    framed = "For full helptext" in err  # tyro's message, boxed on a terminal, ruled with dashes here
    assert framed or (len([x for x in lines if x.startswith("error:")]) == 1 and lines[-1].startswith("error:")), shown
    assert listing(root) == before, f"{shown}\nthe folder changed"
    return err


def fill(argv: list[str], where: dict[str, Path], out_given: bool) -> list[str]:
    argv = [a.format(**{k: str(v) for k, v in where.items()}) for a in argv]
    return argv if out_given else [*argv, "--out", str(where["out"])]


WRITERS = ("train", "sweep", "tune", "paper", "foresight")


@pytest.fixture
def root(tmp_path, cheap_experiments):
    yield tmp_path
    if (tmp_path / "read-only").is_dir():
        (tmp_path / "read-only").chmod(0o755)  # so that pytest can delete it


# ---------------------------------------------------------------------- the table
@pytest.mark.parametrize("program,argv,status", FLAGS, ids=[f"{p} {' '.join(a)}"[:60] for p, a, _ in FLAGS])
def test_a_bad_flag_is_refused_in_one_line_and_writes_nothing(program, argv, status, root, capsys):
    if "{ro}" in argv and getattr(os, "geteuid", lambda: 1)() == 0:
        pytest.skip("root writes into a read-only folder")
    where = places(root)
    given_out = "--out" in argv or program not in WRITERS
    extra = ["--preset", "tiny"] if program in ("train", "sweep", "tune", "paper") and "--preset" not in argv else []
    check_refused(program, fill([*argv, *extra], where, given_out), status, root, capsys)


@pytest.mark.parametrize("name,damage,argv", DAMAGED, ids=[f"{n} {d} {a[0]}" for n, d, a in DAMAGED])
def test_a_damaged_run_folder_is_named_in_one_line_and_left_as_it_is(name, damage, argv, root, capsys):
    where = places(root)
    folder = where["sweep" if name == "sweep.json" else "run"]
    (folder / name).write_bytes(DAMAGE[damage])
    err = check_refused(argv[0], fill(argv[1:], where, True), 2, root, capsys)
    assert name in err or "run.json" in err or f"{folder} is not a sweep folder" in err, err  # what stops it


def test_the_fuzz_table_covers_every_program():
    assert {p for p, _, _ in FLAGS} == set(PROGRAMS)
    assert len(FLAGS) + len(DAMAGED) >= 77


# ---------------------------------------------------------------------- a strategy
FIELDS = ("--num-lanes", "--num-steps", "--hidden-size", "--chunk-updates", "--test-episodes-per-room", "--seed")


def bad_int(flag):
    """A value out of flag's range: counts start at 1, a seed at 0; either may overflow int64."""
    low = -1 if flag == "--seed" else 0
    return st.one_of(st.integers(max_value=low), st.integers(min_value=2**63, max_value=2**80))


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    case=st.sampled_from(FIELDS).flatmap(lambda f: st.tuples(st.just(f), bad_int(f))),
    program=st.sampled_from(("train", "sweep")),
)
@example(case=("--seed", -1), program="train")
@example(case=("--seed", -1), program="sweep")
@example(case=("--num-lanes", 0), program="train")
def test_any_out_of_range_count_is_refused(case, program, root, capsys, tmp_path_factory):
    flag, value = case
    if program == "sweep" and flag in ("--chunk-updates",):
        flag = "--seeds"
    sub = tmp_path_factory.mktemp("case")
    argv = ["--preset", "tiny", flag, str(value), "--out", str(sub / "out")]
    check_refused(program, argv, 2, sub, capsys)


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    name=st.sampled_from(["run.json", "progress.json", "results.json"]),
    data=st.one_of(
        st.binary(max_size=64), st.sampled_from(list(DAMAGE.values())), st.text(max_size=32).map(str.encode)
    ),
    cut=st.integers(min_value=0, max_value=40),
)
def test_any_damage_to_a_run_file_is_named(name, data, cut, root, capsys, tmp_path_factory):
    sub = tmp_path_factory.mktemp("case")
    folder = started_run(sub / "run")
    whole = (folder / "run.json").read_bytes()
    damaged = whole[:cut] if name == "run.json" and not data else data
    if damaged == whole or (name != "run.json" and not damaged.strip()):
        damaged = b"\x00"  # a file that parses is not damage; an empty one of these is read as damage too
    (folder / name).write_bytes(damaged)
    check_refused("train", ["--resume", "--out", str(folder)], 2, sub, capsys)
