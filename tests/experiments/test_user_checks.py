"""Every check before anything is written, and typed configs (issue 80, items 2 and 3).

Item 3: a `Config` field takes a value of its own type (`Config.__post_init__`,
`config.check_type`, from the dataclass's field types): a string for a bool, a tuple or a
number is refused in one line; an int for a float, a list for a tuple and numpy scalars are
taken, as plain Python values. `num_actions` and `imagination_layer_sizes` are checked
against what the agent supports, and a room type's name alone reads as that one room type
in `envs.make`, `Config` and `evaluate_policy` alike. Every run.json config kept in
docs/data still loads.

Item 2: see the tests below the line "every check before anything is written".
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from foresit_jax.config import ACTIONS, Config, field_types
from study_data import ARCHIVES, read_archive_json


# ---------------------------------------------------------------------- typed configs
@pytest.mark.parametrize(
    "fields, message",
    [
        (dict(method="a3c", priors="False"), "priors must be a bool, got 'False' (str)"),
        (dict(priors=0), "priors must be a bool, got 0 (int)"),
        (dict(maml_first_order="true"), "maml_first_order must be a bool, got 'true' (str)"),
        (dict(learning_rate="1e-3"), "learning_rate must be a float, got '1e-3' (str)"),
        (dict(gamma="0.9"), "gamma must be a float, got '0.9' (str)"),
        (dict(progress_reward=True), "progress_reward must be a float, got True (bool)"),
        (dict(perception_range="4"), "perception_range must be a float or None, got '4' (str)"),
        (dict(num_lanes="16"), "num_lanes must be an int, got '16' (str)"),
        (dict(num_lanes=16.0), "num_lanes must be an int, got 16.0 (float)"),
        (dict(method=3), "method must be a str, got 3 (int)"),
        (dict(imagination_layer_sizes="32,512"), "imagination_layer_sizes must be a tuple of ints, got '32,512' (str)"),
        (dict(imagination_layer_sizes=(32, "512")), "imagination_layer_sizes must be a tuple of ints"),
        (dict(imagination_layer_sizes=(32.0, 512)), "imagination_layer_sizes must be a tuple of ints"),
        (dict(room_types=("bathroom", 1)), "room_types must be a tuple of strs"),
    ],
)
def test_a_value_of_another_type_is_refused_naming_the_field_and_type(fields, message):
    with pytest.raises(ValueError) as e:
        Config(**fields)
    assert str(e.value).startswith(message) and "\n" not in str(e.value), str(e.value)


def test_ints_for_floats_lists_for_tuples_and_numpy_scalars_are_taken_as_plain_values():
    config = Config(
        method="a3c",
        learning_rate=np.float32(1e-3),
        num_lanes=np.int64(5),
        priors=np.bool_(True),
        gamma=1,
        perception_range=np.int32(4),
        imagination_layer_sizes=[np.int64(32), 16, 512],
        room_types=["bathroom", np.str_("kitchen")],
    )
    assert type(config.learning_rate) is float and config.learning_rate == pytest.approx(1e-3)
    assert type(config.num_lanes) is int and config.num_lanes == 5
    assert config.priors is True and config.gamma == 1 and type(config.perception_range) is int
    assert config.imagination_layer_sizes == (32, 16, 512) and type(config.imagination_layer_sizes[0]) is int
    assert config.room_types == ("bathroom", "kitchen") and type(config.room_types[1]) is str
    hash(config)  # a jit static argument
    json.dumps(dataclasses.asdict(config))  # run.json
    assert Config(imagination_layer_sizes=np.array([32, 512]), hidden_size=512).imagination_layer_sizes == (32, 512)
    assert dataclasses.replace(config, learning_rate=np.float64(3e-4)).learning_rate == 3e-4


def test_every_field_has_a_type_the_check_knows():
    """The check is made from the dataclass's types: a field of a new type must be taught to it."""
    kinds = {str(t) for t in field_types().values()}
    assert kinds <= {
        "<class 'str'>",
        "<class 'bool'>",
        "<class 'int'>",
        "<class 'float'>",
        "typing.Optional[float]",
        "tuple[str, ...]",
        "tuple[int, ...]",
    }, kinds


def test_num_actions_is_the_environments():
    from envs import catalog

    assert ACTIONS == catalog.ACTIONS and Config().num_actions == catalog.NUM_ACTIONS
    for n in (3, 5, 7):
        with pytest.raises(ValueError, match=f"num_actions must be 6, the environment's actions .*got {n}"):
            Config(num_actions=n)


def test_imagination_layer_sizes_any_number_of_layers_the_last_a_state():
    """f_w (`networks.ImaginationNet`) is one tanh layer per width, any number of them; its
    output is an imagined state, of hidden_size units."""
    assert Config(hidden_size=32, imagination_layer_sizes=(32,)).imagination_layer_sizes == (32,)
    assert len(Config(hidden_size=32, imagination_layer_sizes=(8,) * 9 + (32,)).imagination_layer_sizes) == 10
    with pytest.raises(ValueError, match="must give at least one width: f_w is one tanh layer per width"):
        Config(imagination_layer_sizes=())
    with pytest.raises(ValueError, match="must be positive ints"):
        Config(hidden_size=32, imagination_layer_sizes=(0, 32))
    with pytest.raises(ValueError, match=r"imagination_layer_sizes\[-1\] \(64\) must equal hidden_size \(32\)"):
        Config(hidden_size=32, imagination_layer_sizes=(32, 64))


def test_a_room_types_name_alone_is_that_room_type_in_config_envs_and_evaluate():
    import jax

    import envs
    from envs.gridnav import room_names

    assert Config(room_types="bathroom").room_types == ("bathroom",)
    _, params = envs.make(room_types="bathroom")
    _, one = envs.make(room_types=("bathroom",))
    assert all(jax.tree.leaves(jax.tree.map(np.array_equal, params, one)))
    # evaluate_policy and Evaluator.evaluate read `room_types` through room_names
    assert room_names("bathroom") == ("bathroom",) == room_names(("bathroom",))
    assert room_names(None) == room_names(()) == ("kitchen", "living_room", "bedroom", "bathroom")
    for bad in ("bath", ("bathroom", "bathroom")):
        with pytest.raises(ValueError, match="room type"):
            room_names(bad)


def test_evaluate_policy_takes_a_room_types_name_alone(monkeypatch):
    """evaluate_policy plays the rooms `room_names` gives (a name alone: that room), not its letters."""
    from foresit_jax import evaluate

    played = []
    monkeypatch.setattr(evaluate.Evaluator, "_per_room", lambda self, rooms, *a, **k: played.append(rooms))
    config = Config(method="a3c", hidden_size=32, attention_size=32, value_hidden=32, imagination_layer_sizes=(32,))
    policy = lambda params, carry, obs, first, key: (obs, carry)  # noqa: E731 (never called here)
    evaluate.evaluate_policy(policy, None, lambda n: (), config, "val", episodes_per_room=1, room_types="bathroom")
    evaluate.evaluate_policy(policy, None, lambda n: (), dataclasses.replace(config, room_types="kitchen"), "val", 1)
    assert played == [("bathroom",), ("kitchen",)]


@pytest.fixture(scope="module")
def archived_configs() -> dict[str, dict]:
    return {
        f"{archive}:{name}": info["config"]
        for archive in ARCHIVES
        for name, info in read_archive_json(archive).items()
        if name.endswith("/run.json")
    }


def test_every_archived_runs_config_still_loads(archived_configs):
    """Each run.json's config in docs/data rebuilds as its loaders rebuild it
    (`experiments.running.run.read`, `models.read_trained`, `experiments.evaluate`:
    `Config(**info["config"])`), to the values it records (a field added since takes its default)."""
    assert len(archived_configs) >= 32
    for name, recorded in archived_configs.items():
        try:
            config = Config(**recorded)
        except (TypeError, ValueError) as e:
            pytest.fail(f"{name}: {e}")
        rebuilt = json.loads(json.dumps(dataclasses.asdict(config)))
        assert {k: rebuilt[k] for k in recorded} == recorded, name


# ---------------------------------------------------------------------- every check before anything is written
from cli_helpers import cli_error  # noqa: E402 (the section's helper, shared)


@pytest.mark.parametrize("chunks", ["0", "-1"])
def test_train_refuses_a_stop_after_chunks_below_one_before_writing(chunks, tmp_path, capsys):
    from experiments import train

    out = tmp_path / "run"
    line = cli_error(train.cli, ["--preset", "tiny", "--out", out, "--stop-after-chunks", chunks], capsys)
    assert f"--stop-after-chunks must be >= 1 (train at least one chunk), got {chunks}" in line
    assert not out.exists()


def test_sweep_refuses_a_negative_stop_after_chunks_before_writing(tmp_path, capsys):
    from experiments import sweep, tune

    out = tmp_path / "sweep"
    argv = ["--preset", "tiny", "--methods", "a3c", "--seeds", "1", "--out", out, "--stop-after-chunks", "-1"]
    assert "--stop-after-chunks must be >= 0 (0 trains nothing), got -1" in cli_error(sweep.cli, argv, capsys)
    argv = ["--preset", "tiny", "--methods", "a3c", "--grid", "learning_rate=1e-3", "--seeds", "1", "--out", out]
    assert "--stop-after-chunks must be >= 0" in cli_error(tune.cli, [*argv, "--stop-after-chunks", "-2"], capsys)
    assert not out.exists()


def test_a_sweep_arm_too_long_for_a_folder_name_is_refused_before_writing(tmp_path, capsys):
    from experiments import sweep

    arm = "a3c@learning_rate=0." + "0" * 300 + "1"  # parses: a learning rate of 1e-301
    out = tmp_path / "sweep"
    line = cli_error(sweep.cli, ["--preset", "tiny", "--methods", "a3c", arm, "--seeds", "1", "--out", out], capsys)
    assert f"is {len(arm)} bytes, longer than the 255 a folder name can have" in line and "shorten it" in line
    assert not out.exists()


def test_an_out_too_long_for_the_file_system_is_one_line_and_makes_nothing(tmp_path, capsys):
    from experiments import sweep, train

    out = tmp_path / "made" / ("x" * 300) / "run"
    line = cli_error(train.cli, ["--preset", "tiny", "--out", out], capsys)
    assert "is 300 bytes, longer than the 255 a file or folder name can have; choose a shorter one" in line
    line = cli_error(train.cli, ["--preset", "tiny", "--out", out, "--resume"], capsys)
    assert "longer than the 255" in line
    line = cli_error(sweep.cli, ["--preset", "tiny", "--methods", "a3c", "--seeds", "1", "--out", out], capsys)
    assert "longer than the 255" in line
    deep = tmp_path.joinpath(*["d" * 200] * 25)  # every name short, the path past 4096 bytes
    assert "choose a shorter one" in cli_error(train.cli, ["--preset", "tiny", "--out", deep], capsys)
    assert list(tmp_path.iterdir()) == []


def test_a_symbolic_link_loop_or_a_dangling_link_in_out_is_one_line(tmp_path, capsys):
    from experiments import evaluate, train

    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    (tmp_path / "nowhere").symlink_to(tmp_path / "gone")
    for out in (tmp_path / "a", tmp_path / "a" / "run"):
        line = cli_error(train.cli, ["--preset", "tiny", "--out", out], capsys)
        assert f"{tmp_path / 'a'} is a symbolic link that leads back to itself (a loop)" in line, line
    line = cli_error(train.cli, ["--preset", "tiny", "--out", tmp_path / "nowhere" / "run"], capsys)
    assert f"is a symbolic link to {tmp_path / 'gone'}, which is not there" in line
    line = cli_error(evaluate.cli, ["--run", tmp_path / "a" / "run"], capsys)  # read before any claim
    assert f"{tmp_path / 'a'} is a symbolic link that leads back to itself (a loop)" in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "b", "nowhere"]


def test_os_errors_a_user_causes_are_one_line_wherever_they_come_from(capsys):
    """The backstop (`errors.run_cli`): ENAMETOOLONG and ELOOP raised anywhere are one line with a hint."""
    import errno
    import os

    from experiments import errors

    @dataclasses.dataclass
    class Args:
        code: int = 0

    def main(args):
        raise OSError(args.code, os.strerror(args.code), "/x/" + "y" * 400)

    for code, hint in ((errno.ENAMETOOLONG, "choose a shorter path"), (errno.ELOOP, "leads back to itself")):
        line = cli_error(lambda argv: errors.run_cli(Args, main, argv), ["--code", code], capsys)
        assert hint in line and len(line) < 300, line


def test_evaluate_refuses_a_read_only_run_folder_before_any_work(tmp_path, capsys, monkeypatch):
    """A read-only folder, simulated (root writes in one): `claim` asks the OS (`os.access`)
    before taking the lock, so evaluate stops before it loads or plays anything."""
    import os

    from experiments import evaluate, rundir

    run = tmp_path / "run"
    run.mkdir()
    info = read_archive_json("replication_3x.tar.xz")["replication_3x/methods/a3c@learning_rate=1e-3/run.json"]
    (run / "run.json").write_text(json.dumps(info))
    real = os.access
    monkeypatch.setattr(rundir.os, "access", lambda p, mode: False if str(p) == str(run) else real(p, mode))
    monkeypatch.setattr(evaluate, "read_trained", None)  # evaluating would fail on it: it must not get there
    line = cli_error(evaluate.cli, ["--run", run, "--split", "val"], capsys)
    assert line.startswith(f"error: {run} is read-only") and "make it writable" in line, line
    assert sorted(p.name for p in run.iterdir()) == ["run.json"]  # no .lock, no results


# ---------------------------------------------------------------------- Ctrl-C
def test_the_first_ctrl_c_asks_to_stop_and_the_second_aborts(capsys):
    from experiments.running import loop

    request = loop.StopRequest()
    assert not request.requested
    request()  # the first Ctrl-C: a request, no exception
    assert request.requested and "stopping after the current chunk" in capsys.readouterr().err
    with pytest.raises(KeyboardInterrupt):
        request()  # the second: abort now


def test_the_handler_is_installed_for_a_run_and_restored_after_and_the_loop_checks_it():
    import signal

    from experiments.running import loop

    before = signal.getsignal(signal.SIGINT)
    sizes = []
    with loop.interruptible() as request:
        assert signal.getsignal(signal.SIGINT) is request and not loop.stop_requested()
        for n in loop.chunk_sizes(0, 10, 2, [None]):
            sizes.append(n)
            if len(sizes) == 2:
                request()  # Ctrl-C during the second chunk: it ends, no third starts
    assert sizes == [2, 2]
    assert signal.getsignal(signal.SIGINT) is before and not loop.stop_requested()
    assert list(loop.chunk_sizes(0, 10, 2, [None])) == [2] * 5  # no run in progress, nothing asked


def test_a_second_ctrl_c_is_one_line_with_status_130(capsys):
    from experiments import errors

    @dataclasses.dataclass
    class Args:
        x: int = 0

    def main(args):
        raise KeyboardInterrupt

    line = cli_error(lambda argv: errors.run_cli(Args, main, argv), [], capsys, code=130)
    assert "interrupted (Ctrl-C)" in line and "--resume" in line


@pytest.mark.slow
def test_ctrl_c_stops_a_run_after_its_chunk_checkpointed_and_resume_finishes_it(tmp_path, capsys, monkeypatch):
    """A tiny train run (4 updates, chunks of 2) whose stop flag is set as a first Ctrl-C
    sets it, during the first chunk: it stops after that chunk, checkpointed, says so, and
    --resume trains it to the end."""
    import contextlib

    from experiments import rundir, train
    from experiments.running import loop
    from experiments.running.run import Run

    real_interruptible, real_record = loop.interruptible, Run.record

    @contextlib.contextmanager
    def ctrl_c_in_the_first_chunk():
        with real_interruptible() as request:

            def record(self, *args, **kwargs):
                request()  # as the SIGINT handler does on a first Ctrl-C
                real_record(self, *args, **kwargs)

            with monkeypatch.context() as m:
                m.setattr(Run, "record", record)
                yield request

    monkeypatch.setattr(loop, "interruptible", ctrl_c_in_the_first_chunk)
    out = tmp_path / "run"
    capsys.readouterr()
    assert train.main(train.Args(method="a3c", preset="tiny", out=out, progress=False)) == {"stopped_at": 2}
    assert "interrupted at update 2; continue with --resume" in capsys.readouterr().out
    assert rundir.checkpoint_at(out, 2).is_dir() and rundir.read_progress(out)["done"] == 2
    assert not (out / rundir.RESULTS_FILE).exists()
    monkeypatch.setattr(loop, "interruptible", real_interruptible)
    train.main(train.Args(out=out, resume=True, progress=False))
    assert rundir.read_results(out)["updates"] == 4 and (out / "results_test.json").is_file()
