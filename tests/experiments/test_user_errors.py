"""A user's names and errors (issue 71): `experiments` lists what it imports lazily, a
UserError is a ValueError, and a run folder that is not there is a RunNotFound, which
`except FileNotFoundError` catches too, naming what is missing."""

import dataclasses

import pytest

import experiments
from experiments.errors import RunNotFound, UserError
from experiments import rundir


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


# ---------------------------------------------------------------------- sizes (issue 71)
def test_a_window_of_observations_is_counted_by_hand():
    from experiments.running import presets
    from foresit_jax.config import Config

    # savn: a view of 3 rows x 16 rays x 23 channels and a 300-d word vector, float32
    assert presets.observation_bytes(Config(setup="savn")) == (3 * 16 * 23 + 300) * 4 == 5616
    # org: 27 channels, 22 categories, 22 x 7 detection features
    assert presets.observation_bytes(Config(setup="org")) == (3 * 16 * 27 + 22 + 22 * 7) * 4
    config = Config(num_lanes=8, num_steps=16)
    assert presets.window_bytes(config, seeds=3) == 3 * 8 * 17 * 5616


def test_sizes_past_their_bounds_are_refused_naming_the_bound_unless_allowed():
    from experiments.running import presets
    from foresit_jax.config import Config

    config = Config(num_lanes=8, num_steps=16)
    need = presets.window_bytes(config, seeds=2)
    presets.check_sizes(config, seeds=2, memory=need)  # exactly fits
    with pytest.raises(
        ValueError, match=r"2 seed\(s\) x 8 lanes x 17 steps of 5616-byte observations .* --allow-large"
    ):
        presets.check_sizes(config, seeds=2, memory=need - 1)
    presets.check_sizes(config, seeds=2, memory=need - 1, allow_large=True)
    presets.check_sizes(Config(num_updates=10**7), memory=2**40)
    with pytest.raises(ValueError, match="bound of 10,000,000 updates"):
        presets.check_sizes(Config(num_updates=10**7 + 1), memory=2**40)
    with pytest.raises(ValueError, match="bound of 4096 seeds"):
        presets.check_sizes(Config(), seeds=4097, memory=2**60)
    schedule = presets.PRESETS["quick"][1]
    with pytest.raises(ValueError, match="--test-episodes-per-room 100001 is past the bound"):
        presets.check_sizes(Config(), schedule=dataclasses.replace(schedule, test_episodes_per_room=10**5 + 1))
    for allow_large in (False, True):  # no flag lifts int32's
        with pytest.raises(ValueError, match="--num-lanes 2147483648 is past 2\\*\\*31-1"):
            presets.check_sizes(Config(num_lanes=2**31), allow_large=allow_large)


# ---------------------------------------------------------------------- --resume's ignored flags
def test_resume_names_in_one_line_the_flags_it_ignored(tmp_path, capsys):
    from experiments import sweep, train
    from experiments.errors import run_cli
    from experiments.running import flags, sweeps

    rundir.write_started_args(tmp_path / "sweep.json", sweeps.Sweep(preset="tiny", seeds=2, out=tmp_path), ())

    def resumed(argv):
        capsys.readouterr()
        args = run_cli(
            sweep.Args,
            lambda a: rundir.resumed_args(a, "sweep.json", "sweep", keep=flags.INVOCATION),
            ["--out", str(tmp_path), "--resume", *argv],
        )
        return args, capsys.readouterr().err

    args, err = resumed(["--preset", "quick", "--seeds", "5", "--setup", "savn"])  # all at their defaults
    assert (args.preset, args.seeds) == ("tiny", 2)
    assert err.count("\n") == 1 and "ignored --seeds 5 (started with 2), --preset quick (started with tiny)" in err, err
    assert "--setup" not in err  # given, but what the sweep has
    assert resumed([])[1] == ""  # nothing given, nothing said
    with pytest.raises(SystemExit):  # another value is refused, as before
        resumed(["--preset", "house"])

    info = {
        "arm": "a3c",
        "preset": "tiny",
        "seeds": [3],
        "config": {"setup": "savn"},
        "schedule": {"chunk_updates": 2, "test_episodes_per_room": 2, "val_episodes_per_room": 2},
    }
    ignored = run_cli(
        train.Args, lambda a: train.resume_ignored(a, info), ["--resume", "--seed", "0", "--preset", "quick"]
    )
    assert ignored == ["--preset quick (the run has tiny)", "--seed 0 (the run has 3)"]
    assert (
        train.resume_ignored(train.Args(seed=0, preset="quick"), info) == []
    )  # outside run_cli nothing is known given
