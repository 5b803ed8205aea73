"""Runs a user can trust under faults: one writer per folder, no NaN model reported as a
result, checkpoints verified, resume that says what it ignores, bad input refused.

Each test below fails on the code before these checks existed (the issue's cases): two
processes on one folder; a step that leaves NaN weights behind a finite loss; corrupt and
truncated checkpoints; resume with contradicting flags; inf in a Config; actions out of
range; a metrics line cut by a kill.
"""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from cli_helpers import cli_error

import envs
import train_helpers as H
from benchmarks import search_learner
from experiments import evaluate as evaluate_cli
from experiments import sweep
from experiments import train as train_cli
from experiments import errors
from experiments.running import checkpoint, loop
from experiments import rundir
from experiments.running.run import counts_of, initial_states, rewind
from foresit_jax.config import Config

REPO = Path(__file__).resolve().parents[2]


# Cheap in-process CLI calls for every test of this module (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("cheap_experiments")


def tiny(out: Path, **kwargs) -> train_cli.Args:
    return train_cli.Args(method="a3c", preset="tiny", seed=1, out=out, progress=False, **kwargs)


def snapshot(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


one_line_error = cli_error  # tests/cli_helpers.py's


@pytest.fixture(scope="module")
def run6(tmp_path_factory, cheap_experiments):
    """An uninterrupted tiny a3c run of 6 updates (chunks of 2): the reference."""
    out = tmp_path_factory.mktemp("reliability") / "uninterrupted"
    train_cli.main(tiny(out, num_updates=6))
    return out


# ---------------------------------------------------------------------- 1. one writer per folder
HOLDER = """
import os, sys, time
from pathlib import Path
sys.path.insert(0, {repo!r})
from experiments import errors
from experiments.running import checkpoint, loop
from experiments import rundir
Path({ready!r}, str(os.getpid())).write_text("")
while not Path({go!r}).exists():
    time.sleep(0.001)
try:
    rundir.prepare_run_dir(Path({out!r}), resume=False, overwrite=False)
    (Path({out!r}) / "run.json").write_text("{{}}")
    print("claimed", flush=True)
    time.sleep({hold})
except errors.UserError as e:
    print("refused:", e, flush=True)
"""


def start_holder(out: Path, ready: Path, go: Path, hold: float) -> subprocess.Popen:
    code = textwrap.dedent(HOLDER.format(repo=str(REPO), ready=str(ready), go=str(go), out=str(out), hold=hold))
    return subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, env={**os.environ, "JAX_PLATFORMS": "cpu"}
    )


def test_two_processes_started_at_the_same_instant_on_one_folder_one_is_refused(tmp_path):
    out, ready, go = tmp_path / "run", tmp_path / "ready", tmp_path / "go"
    ready.mkdir()
    procs = [start_holder(out, ready, go, hold=3.0) for _ in range(2)]
    deadline = time.time() + 120
    while len(list(ready.iterdir())) < 2 and time.time() < deadline:  # both imported, waiting on one flag
        time.sleep(0.05)
    go.write_text("")
    outputs = sorted(p.communicate(timeout=60)[0].strip() for p in procs)
    assert outputs[0] == "claimed", outputs
    # Refused by the lock, or (had the first one written run.json and let go) as a run
    # folder that exists; never both accepted.
    assert outputs[1].startswith("refused:"), outputs
    assert "being written by another process (pid" in outputs[1] or "already exists" in outputs[1], outputs


@pytest.mark.slow
def test_a_run_held_by_another_process_is_refused_in_one_line_and_left_as_it_was(run6, tmp_path, capsys):
    out = tmp_path / "held"
    shutil.copytree(run6, out)
    (out / rundir.LOCK_FILE).unlink()
    before = snapshot(out)
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            textwrap.dedent(f"""
        import sys, time
        sys.path.insert(0, {str(REPO)!r})
        from pathlib import Path
        from experiments import errors
        from experiments.running import checkpoint, loop
        from experiments import rundir
        rundir.claim(Path({str(out)!r}))
        print("holding", flush=True)
        time.sleep(30)
        """),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "holding"
        for argv in (["--out", out, "--resume"], ["--preset", "tiny", "--out", out, "--overwrite"]):
            line = one_line_error(train_cli.cli, argv, capsys)
            assert f"pid {holder.pid}" in line, line
        line = one_line_error(evaluate_cli.cli, ["--run", out, "--overwrite"], capsys)
        assert f"pid {holder.pid}" in line
    finally:
        holder.kill()
        holder.wait()
    lock = out / rundir.LOCK_FILE
    assert {k: v for k, v in snapshot(out).items() if k != rundir.LOCK_FILE} == before
    assert lock.exists()  # left behind by the killed holder: it locks nothing now
    rundir.claim(out)


def test_prepare_run_dir_claims_the_folder_and_ignores_its_own_lock_file(tmp_path):
    out = tmp_path / "out"
    rundir.prepare_run_dir(out, resume=False, overwrite=False)
    assert (out / rundir.LOCK_FILE).read_text() == str(os.getpid())
    rundir.prepare_run_dir(out, resume=False, overwrite=False)  # only the lock: still empty
    with pytest.raises(errors.UserError, match="is a file"):
        rundir.claim(out / rundir.LOCK_FILE)


# ---------------------------------------------------------------------- 2-3. non-finite and diverging
@pytest.mark.slow
def test_a_step_that_leaves_inf_weights_behind_a_finite_loss_is_not_reported(tmp_path, capsys):
    """lr 1e39 is finite as a Python float but inf in float32: the first Adam step makes
    the weights inf while the loss (computed before the step) is finite."""
    out = tmp_path / "inf_step"
    line = one_line_error(
        train_cli.cli,
        [
            "--method",
            "a3c",
            "--preset",
            "tiny",
            "--out",
            out,
            "--no-progress",
            "--learning-rate",
            "1e39",
            "--num-updates",
            "1",
        ],
        capsys,
        code=1,
    )
    assert "non-finite parameters after update 1" in line and "no checkpoint was written" in line, line
    assert not list((out / "checkpoints").glob("*")) and not (out / "results_test.json").exists()


@pytest.mark.slow
def test_a_sweep_names_the_seed_whose_weights_went_non_finite(tmp_path, capsys):
    """The same fault in a sweep (the loop train and sweep share, experiments.running.loop)."""
    out = tmp_path / "inf_sweep"
    line = one_line_error(
        sweep.cli,
        [
            "--methods",
            "a3c",
            "--seeds",
            "2",
            "--seed",
            "3",
            "--preset",
            "tiny",
            "--out",
            out,
            "--no-progress",
            "--learning-rate",
            "1e39",
            "--num-updates",
            "1",
        ],
        capsys,
        code=1,
    )
    assert "a3c: non-finite parameters after update 1 in seed(s) [3, 4]" in line, line
    assert "no checkpoint was written" in line and not (out / "methods" / "a3c" / "progress.json").exists(), line


@pytest.mark.slow
def test_nan_weights_in_a_later_chunk_stop_the_run_naming_a_checkpoint_that_exists(tmp_path, capsys, monkeypatch):
    out = tmp_path / "nan_later"
    train_cli.main(tiny(out, stop_after_chunks=1))
    trainer = H.cached_trainer(Config(**rundir.read_run_info(out)["config"]))
    real_run = trainer.run

    def poisoned(state, env_params, n, **kwargs):  # the chunk's loss stays finite; its weights do not
        state, metrics = real_run(state, env_params, n, **kwargs)
        return state._replace(params=jax.tree.map(lambda x: x * jnp.nan, state.params)), metrics

    monkeypatch.setattr(trainer, "run", poisoned)
    line = one_line_error(train_cli.cli, ["--out", out, "--resume", "--no-progress"], capsys, code=1)
    assert "non-finite parameters after update 4" in line and "last checkpoint (update 2, finite)" in line, line
    manager = checkpoint.checkpoint_manager(out / "checkpoints", 10)
    assert manager.all_steps() == [2]
    states, best = initial_states(trainer, [1])
    assert loop.finite_seeds(checkpoint.restore(manager, 2, {"states": states, "best": best}))
    assert [r["update"] for r in rundir.read_rows(out / "metrics")] == [1, 2]


def test_finite_seeds_finds_the_seed_with_a_nan():
    tree = {"w": np.ones((3, 4), np.float32), "step": np.arange(3), "b": np.zeros((3,), np.float32)}
    assert loop.finite_seeds(tree, 3).tolist() == [True, True, True] and loop.finite_seeds(tree)
    tree["w"][1, 2] = np.inf
    assert loop.finite_seeds(tree, 3).tolist() == [True, False, True] and not loop.finite_seeds(tree)


def test_divergence_short_of_nan_is_warned_of():
    normal = {"losses/grad_norm": [0.5, 3.0], "losses/total_loss": [1.2, -0.4], "losses/entropy": [1.7, 0.3]}
    assert loop.divergence(normal) is None
    for name, values, says in (
        ("losses/total_loss", [1.0, 1e33], "total_loss reached 1e+33"),
        ("losses/grad_norm", [np.inf, 1.0], "grad_norm reached inf"),
        ("losses/entropy", [0.5, 0.0], "entropy fell to 0"),
    ):
        warning = loop.divergence({**normal, name: values})
        assert warning is not None and says in warning, warning


# ---------------------------------------------------------------------- 4. checkpoints verified
@pytest.mark.slow
def test_a_corrupt_checkpoint_is_one_line_and_the_good_results_stay(run6, tmp_path, capsys):
    out = tmp_path / "corrupt_best"
    shutil.copytree(run6, out)
    (out / rundir.LOCK_FILE).unlink()
    good = (out / "results_test.json").read_bytes()
    step = out / "checkpoints" / "6"  # the one evaluate reads the selected model from
    H.corrupt_checkpoint(step, "flipped")
    line = one_line_error(evaluate_cli.cli, ["--run", out, "--overwrite"], capsys)
    assert f"checkpoint {step} is corrupt or truncated" in line
    assert (out / "results_test.json").read_bytes() == good


@pytest.mark.slow
def test_a_checkpoint_saved_before_checksums_still_restores(run6, tmp_path):
    manager = checkpoint.checkpoint_manager(run6 / "checkpoints", 10)
    step = manager.latest_step()
    states, best = initial_states(H.cached_trainer(Config(**rundir.read_run_info(run6)["config"])), [1])
    like = {"states": states, "best": best}
    copy = tmp_path / "old"
    shutil.copytree(run6 / "checkpoints", copy)
    (copy / str(step) / checkpoint.CHECKSUM_FILE).unlink()
    old = checkpoint.checkpoint_manager(copy, 10)
    assert checkpoint.intact_step(old) == (step, [])
    H.assert_trees_bitwise_equal(checkpoint.restore(old, step, like), checkpoint.restore(manager, step, like))


# ---------------------------------------------------------------------- 5. resume and its flags
@pytest.mark.slow
def test_resume_refuses_flags_that_contradict_the_run_and_extends_with_num_updates(run6, tmp_path, capsys):
    out = tmp_path / "flags"
    train_cli.main(tiny(out, num_updates=4))
    for flag, value, says in (
        ("--method", "a3c+critic", "--method a3c+critic (the run has a3c)"),
        ("--seed", 3, "--seed 3 (the run has 1)"),
        ("--learning-rate", 0.5, "--learning-rate 0.5 (the run has"),
        ("--chunk-updates", 1, "--chunk-updates 1 (the run has 2)"),
    ):
        line = one_line_error(train_cli.cli, ["--out", out, "--resume", flag, value], capsys)
        assert says in line, line
    line = one_line_error(train_cli.cli, ["--out", out, "--resume", "--num-updates", 2], capsys)
    assert "would shorten" in line
    capsys.readouterr()
    train_cli.main(train_cli.Args(out=out, resume=True, num_updates=6, progress=False))
    said = capsys.readouterr().out
    assert "extending" in said and "its 4-update report is kept in report_4_updates/" in said, said
    assert rundir.read_run_info(out)["config"]["num_updates"] == 6
    assert rundir.read_json(out / "results_4_updates.json")["updates"] == 4
    assert sorted(p.name for p in (out / "report_4_updates").iterdir()) == sorted(train_cli.REPORT_FILES)
    # The same updates as a run of 6 from the start (the validation follows the chunks:
    # here too they end at 2, 4, 6).
    assert (out / "metrics.jsonl").read_bytes() == (run6 / "metrics.jsonl").read_bytes()
    assert (out / "results_test.json").read_bytes() == (run6 / "results_test.json").read_bytes()
    # An extension whose report would replace one kept before is refused before anything moves.
    (out / "report_6_updates").mkdir()
    (out / "report_6_updates" / "results_test.json").write_text("mine")
    before = snapshot(out)
    line = one_line_error(train_cli.cli, ["--out", out, "--resume", "--num-updates", 8], capsys)
    assert "already holds report_6_updates/results_test.json; move them first" in line, line
    assert {k: v for k, v in snapshot(out).items() if k != rundir.LOCK_FILE} == {
        k: v for k, v in before.items() if k != rundir.LOCK_FILE
    }
    # The same bytes kept there (an extension killed after moving them, the report then
    # written again by a resume) are this report: the extension goes on.
    shutil.copy(out / "results_test.json", out / "report_6_updates" / "results_test.json")
    train_cli.main(train_cli.Args(out=out, resume=True, num_updates=8, progress=False))
    assert rundir.read_json(out / "report_6_updates" / "results_test.json") == rundir.read_json(
        run6 / "results_test.json"
    )
    assert rundir.read_json(out / "results.json")["updates"] == 8


@pytest.mark.slow
def test_resume_of_a_finished_run_leaves_its_files_alone(run6, tmp_path, capsys):
    out = tmp_path / "finished"
    shutil.copytree(run6, out)
    (out / rundir.LOCK_FILE).unlink()
    with open(out / "results_test.md", "a") as f:
        f.write("\nmy note\n")
    before = snapshot(out)
    capsys.readouterr()
    results = train_cli.main(train_cli.Args(out=out, resume=True, progress=False))
    assert "nothing to do" in capsys.readouterr().out
    assert {k: v for k, v in snapshot(out).items() if k != rundir.LOCK_FILE} == before
    assert results == rundir.read_json(out / "results_test.json")["results"]


# ---------------------------------------------------------------------- 6. inf in Config
@pytest.mark.parametrize("field", ["learning_rate", "gamma", "entropy_coef", "sigma2_max", "max_grad_norm"])
@pytest.mark.parametrize("value", [float("inf"), float("-inf"), float("nan")])
def test_config_refuses_non_finite_floats(field, value):
    with pytest.raises(ValueError, match=f"{field} must be a finite number"):
        Config(**{field: value})


def test_train_with_an_infinite_learning_rate_is_refused_before_anything_is_written(tmp_path, capsys):
    out = tmp_path / "lr_inf"
    line = one_line_error(train_cli.cli, ["--preset", "tiny", "--out", out, "--learning-rate", "inf"], capsys)
    assert "learning_rate must be a finite number" in line and not out.exists()


# ---------------------------------------------------------------------- 7. actions
@pytest.fixture(scope="module")
def bathroom():
    env, params = envs.make(room_types=["bathroom"])
    obs, state = env.reset(jax.random.PRNGKey(3), params)
    return env, params, state


@pytest.mark.parametrize("action", [6, 7, -1, 100, np.uint8(255), np.int64(9)])
def test_an_integer_action_out_of_range_is_the_documented_no_op_step(bathroom, action):
    env, params, state = bathroom
    _, after, reward, terminated, truncated, info = env.step(jax.random.PRNGKey(0), state, action, params)
    assert (
        float(reward) == float(np.float32(params.step_penalty)) and not bool(terminated) and not bool(info["success"])
    )
    for name in ("agent_pos", "heading", "horizon"):
        np.testing.assert_array_equal(getattr(after, name), getattr(state, name))
    assert int(after.time) == int(state.time) + 1


@pytest.mark.parametrize("action", [1.0, 2.7, True, jnp.float32(0)])
def test_a_non_integer_action_is_a_type_error(bathroom, action):
    env, params, state = bathroom
    with pytest.raises(TypeError, match="must be an integer"):
        env.step(jax.random.PRNGKey(0), state, action, params)


def test_check_actions_raises_on_an_out_of_range_action_under_jit_and_vmap(bathroom):
    _, params, state = bathroom
    env = envs.GridNav(check_actions=True)
    step = jax.jit(jax.vmap(env.step, in_axes=(None, None, 0, None)))
    jax.block_until_ready(step(jax.random.PRNGKey(0), state, jnp.arange(6), params))  # 0..5: fine
    with pytest.raises(Exception, match="action 7 is outside 0..5"):
        jax.block_until_ready(step(jax.random.PRNGKey(0), state, jnp.array([0, 7]), params))


@pytest.mark.parametrize(
    "room_types, says",
    [([], "at least one room type"), ([1.5], "got 1.5"), ([True], "got True"), (["attic"], "unknown room type")],
)
def test_make_refuses_bad_room_types(room_types, says):
    with pytest.raises(ValueError, match=says):
        envs.make(room_types=room_types)


# ---------------------------------------------------------------------- 8. smaller ones
@pytest.mark.slow
def test_a_metrics_line_cut_by_a_kill_is_dropped_and_the_run_resumes_to_the_same_bytes(run6, tmp_path, capsys):
    out = tmp_path / "cut"
    train_cli.main(tiny(out, num_updates=6, stop_after_chunks=1))
    with open(out / "metrics.jsonl", "a") as f:
        f.write('{"update": 3, "episodes": 1')  # a kill in the middle of an append
    capsys.readouterr()
    train_cli.main(train_cli.Args(out=out, resume=True, progress=False))
    assert "dropped a partial last line" in capsys.readouterr().err
    for name in ("metrics.jsonl", "metrics.csv", "results_test.json"):
        assert (out / name).read_bytes() == (run6 / name).read_bytes(), name


@pytest.mark.slow
def test_a_broken_line_inside_a_metrics_file_or_a_broken_run_json_is_named(tmp_path, capsys):
    out = tmp_path / "broken"
    train_cli.main(tiny(out, stop_after_chunks=1))
    text = (out / "metrics.jsonl").read_text().splitlines()
    (out / "metrics.jsonl").write_text("\n".join([text[0][:10], *text[1:]]) + "\n")
    line = one_line_error(train_cli.cli, ["--out", out, "--resume"], capsys)
    assert f"{out / 'metrics.jsonl'}: line 1 is not valid JSON" in line
    (out / "run.json").write_text('{"method": ')
    line = one_line_error(train_cli.cli, ["--out", out, "--resume"], capsys)
    assert f"{out / 'run.json'} is not valid JSON" in line


def test_out_that_is_a_file_or_under_a_file_is_one_line(tmp_path, capsys):
    a_file = tmp_path / "file"
    a_file.write_text("mine")
    for out, code in ((a_file, 2), (a_file / "run", 2)):
        line = one_line_error(train_cli.cli, ["--preset", "tiny", "--out", out], capsys, code=code)
        assert str(a_file) in line, line
    assert a_file.read_text() == "mine"


def test_a_full_disk_is_one_line_that_says_how_to_continue(tmp_path, capsys, monkeypatch):
    def full(path, x):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(rundir, "write_json", full)
    line = one_line_error(train_cli.cli, ["--preset", "tiny", "--out", tmp_path / "full"], capsys, code=1)
    assert (
        line
        == f"error: {tmp_path / 'full' / 'run.json'}: No space left on device (free some space, then continue with --resume)"
    )


@pytest.mark.slow
def test_a_disk_too_full_for_a_checkpoint_is_one_line_before_orbax_writes(tmp_path, capsys, monkeypatch):
    """(A real full disk, a 20 MB tmpfs with a filler, gave this line, and the run resumed
    to the files of an uninterrupted one once the filler was deleted; orbax failing in the
    middle of a write printed 931 lines.)"""
    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(checkpoint.shutil, "disk_usage", lambda path: usage._replace(free=100_000))
    out = tmp_path / "full_at_checkpoint"
    line = one_line_error(train_cli.cli, ["--preset", "tiny", "--out", out, "--no-progress"], capsys, code=1)
    assert "No space left on device for checkpoint 2" in line and "continue with --resume" in line, line
    assert not list((out / "checkpoints").iterdir())


@pytest.mark.slow
def test_evaluate_on_a_read_only_run_folder_fails_before_evaluating(run6, tmp_path, capsys, monkeypatch):
    """A read-only folder, simulated (these tests may run as root, whom permissions do not
    stop): opening its lock file fails as on a read-only file system, before any work."""
    out = tmp_path / "read_only"
    shutil.copytree(run6, out)
    (out / rundir.LOCK_FILE).unlink()
    real_open = os.open

    def read_only(path, *args, **kwargs):
        if str(path).startswith(str(out)):
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(path))
        return real_open(path, *args, **kwargs)

    monkeypatch.setattr(rundir.os, "open", read_only)
    monkeypatch.setattr(evaluate_cli, "selection", None)  # evaluating would fail on it: it must not get there
    line = one_line_error(evaluate_cli.cli, ["--run", out, "--split", "val"], capsys)
    assert line == f"error: {out / rundir.LOCK_FILE}: {os.strerror(errno.EROFS)}"
    assert not (out / "results_val.json").exists()


def test_search_learner_parses_every_variant_before_training(monkeypatch):
    trained = []
    monkeypatch.setattr(search_learner, "run_variant", lambda args, overrides: trained.append(overrides))
    with pytest.raises(SystemExit, match="item 2"):
        search_learner.main(search_learner.Args(variants=('{"learning_rate": 1e-3}', "{not json")))
    assert trained == []


def test_sweep_rewind_drops_the_chunks_after_a_step_and_reselects():
    progress = {
        "done": 6,
        "curves": [[[0.1, 0.2], [0.3, 0.4]]] * 3,
        "history": [
            [{"update": 2, "SR": 10.0}, {"update": 4, "SR": 30.0}, {"update": 6, "SR": 50.0}],
            [{"update": 2, "SR": 40.0}, {"update": 4, "SR": 40.0}, {"update": 6, "SR": 20.0}],
        ],
        "diagnostics": {"losses/entropy": [[1.0, 1.1], [0.9, 1.0], [0.8, 0.9]]},
        "counts": {"charts/episodes": [[5.0, 6.0], [7.0, 8.0], [9.0, 10.0]]},
        "best_sr": [50.0, 40.0],
        "best_update": [6, 4],
        "numerics": [{"from_update": 0, "platform": "a"}, {"from_update": 6, "platform": "b"}],
    }
    back = rewind(progress, 2)
    assert back["done"] == 2 and len(back["curves"]) == 1 and back["diagnostics"]["losses/entropy"] == [[1.0, 1.1]]
    assert back["counts"] == {"charts/episodes": [[5.0, 6.0]]}
    assert counts_of(back, 1) == {"charts/episodes": 6.0}
    assert counts_of({**back, "counts": {}}, 1) == {}  # recorded in no chunk: no count, not 0
    assert counts_of({**progress, "counts": back["counts"]}, 0) == {}  # in some chunks only: no undercount
    assert back["best_sr"] == [10.0, 40.0] and back["best_update"] == [2, 2]
    assert [len(h) for h in back["history"]] == [1, 1] and back["numerics"] == [{"from_update": 0, "platform": "a"}]
    back = rewind(progress, 4)
    assert back["best_sr"] == [30.0, 40.0] and back["best_update"] == [4, 4]  # a tie: the later model


def test_without_fcntl_the_folder_lock_is_filelocks(tmp_path, monkeypatch):
    """Native Windows has no fcntl: claim() falls back to filelock on the same .lock file,
    and a second holder is refused in one line."""
    filelock = pytest.importorskip("filelock")
    from experiments import errors

    monkeypatch.setattr(rundir, "fcntl", None)
    monkeypatch.setattr(rundir, "_held", {})
    rundir.claim(tmp_path / "a")
    assert (tmp_path / "a" / rundir.LOCK_FILE).exists()
    rundir.claim(tmp_path / "a")  # this process holds it: a no-op
    other = filelock.FileLock(str(tmp_path / "b" / rundir.LOCK_FILE))
    (tmp_path / "b").mkdir()
    with other:  # another holder (filelock's locks are per object, as a second process's would be)
        with pytest.raises(errors.UserError, match="being written by another process"):
            rundir.claim(tmp_path / "b")
    for lock in rundir._held.values():
        lock.release()
