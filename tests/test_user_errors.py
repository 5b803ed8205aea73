"""A user's names and errors (issue 71): `experiments` lists what it imports lazily, a
UserError is a ValueError, and a run folder that is not there is a RunNotFound, which
`except FileNotFoundError` catches too, naming what is missing."""

import pytest

import experiments
from experiments.errors import RunNotFound, UserError
from experiments.running import rundir


def test_dir_lists_the_lazily_imported_names():
    assert {"load", "Policy"} <= set(dir(experiments))
    assert "__getattr__" in dir(experiments)


def test_a_user_error_is_a_value_error_and_a_missing_run_a_file_not_found():
    assert issubclass(UserError, ValueError)
    assert issubclass(RunNotFound, UserError) and issubclass(RunNotFound, FileNotFoundError)


def test_a_missing_run_folder_is_named_missing(tmp_path):
    missing = tmp_path / "no such run"
    with pytest.raises(FileNotFoundError, match="is not there"):
        experiments.load(missing)
    with pytest.raises(RunNotFound, match="is not there"):
        rundir.read_run_info(missing)
    assert not missing.exists()  # nothing was made on the way
    with pytest.raises(RunNotFound, match="is not a run folder"):
        experiments.load(tmp_path)
    (tmp_path / "sweep.json").write_text("{}")
    with pytest.raises(UserError, match="a sweep folder"):
        experiments.load(tmp_path)


def run_cli_raising(error, capsys):
    """`run_cli` over a program that raises `error`: (exit status, stderr)."""
    import dataclasses

    from experiments.errors import run_cli

    @dataclasses.dataclass
    class Args:
        n: int = 0

    def main(args):
        raise error

    with pytest.raises(SystemExit) as exc:
        run_cli(Args, main, [])
    return exc.value.code, capsys.readouterr().err


def test_run_cli_turns_an_overflow_and_xla_out_of_memory_into_one_line(capsys):
    code, err = run_cli_raising(OverflowError("Python int too large to convert to C long"), capsys)
    assert code == 2 and err.count("\n") == 1 and "too large" in err and "smaller --seed" in err
    oom = RuntimeError("RESOURCE_EXHAUSTED: Out of memory while trying to allocate 68719476736 bytes.\nmore")
    code, err = run_cli_raising(oom, capsys)
    assert code == 1 and err.count("\n") == 1 and "out of memory" in err and "--num-lanes" in err
    with pytest.raises(RuntimeError, match="something else"):  # a bug stays a traceback
        run_cli_raising(RuntimeError("something else"), capsys)
