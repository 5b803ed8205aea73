"""experiments: run folders, resume, overwrite protection, non-finite losses, one-line
errors, and every command of the README at a tiny size.

The CLIs are called in-process (`main(Args(...))`, `cli(argv)`): a subprocess re-imports
jax and recompiles everything.  `train_helpers.patch_for_experiments` keeps them cheap
(bathroom-only `tiny` preset, one Trainer per config so every `main()` reuses one
compiled chunk, fast XLA compilation); what the CLIs do is unchanged.
"""

import dataclasses
import importlib
import importlib.util
import json
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest
import tyro

import train_helpers as H
from experiments import evaluate as evaluate_cli
from experiments import presets, runs, sweep
from experiments import train as train_cli
from foresit_jax.config import Config

REPO = Path(__file__).resolve().parents[1]
SEED = 3


@pytest.fixture(scope="module", autouse=True)
def cheap_experiments():
    with pytest.MonkeyPatch.context() as mp:
        H.patch_for_experiments(mp)
        yield


def tiny_args(out: Path, **kwargs) -> train_cli.Args:
    return train_cli.Args(method="a3c+foresit", preset="tiny", seed=SEED, out=out, progress=False, **kwargs)


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory, cheap_experiments):
    """An uninterrupted tiny run (4 updates in 2 chunks): the reference of the resume test."""
    out = tmp_path_factory.mktemp("runs") / "uninterrupted"
    train_cli.main(tiny_args(out))
    return out


def run_config(out: Path) -> Config:
    return Config(**runs.read_run_info(out)["config"])


def restore_latest(out: Path, folder: str = "checkpoints"):
    manager = runs.checkpoint_manager(out / folder, 100)
    like = H.cached_trainer(run_config(out)).init(jax.random.PRNGKey(0))
    if folder == "best":
        from foresit_jax.evaluate import agent_params

        like = agent_params(like, run_config(out).sigma2_max)
    step = manager.latest_step()
    return step, manager.all_steps(), runs.restore(manager, step, like)


def snapshot(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def cli_error(cli, argv, capsys) -> str:
    """Run a CLI that must fail: exit status 2 and exactly one line on stderr, no traceback."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        cli([str(a) for a in argv])
    err = capsys.readouterr().err
    assert exc.value.code == 2, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err
    return lines[0]


# ---------------------------------------------------------------------- training runs
def test_finished_run_folder(finished_run):
    info = runs.read_run_info(finished_run)
    assert (info["method"], info["preset"], info["seed"]) == ("a3c+foresit", "tiny", SEED)
    rows = runs.read_rows(finished_run / "metrics")
    assert [r["update"] for r in rows] == [1, 2, 3, 4]
    assert all(np.isfinite(r["losses/total_loss"]) for r in rows)
    # Running totals: ended episodes, useful frames (packed windows: every step is useful).
    assert rows[-1]["episodes"] == sum(r["charts/episodes"] for r in rows) > 0
    assert rows[-1]["frames"] == rows[-1]["stepped_frames"] == 4 * 4 * 30
    assert [r["update"] for r in runs.read_rows(finished_run / "validation")] == [2, 4]
    results = json.loads((finished_run / "results_test.json").read_text())
    assert results["selected_update"] in (2, 4)
    assert set(results["results"]) == {"bathroom", "overall"}
    assert results["results"]["overall"]["episodes"] == 2
    for name in ("results_test.md", "learning_curve.png", "metrics.csv"):
        assert (finished_run / name).stat().st_size > 0
    step, steps, state = restore_latest(finished_run)
    assert (step, steps) == (4, [2, 4])
    assert int(state.update) == 4
    H.assert_tree_finite(state)


def test_resume_after_a_kill_ends_bit_identical_to_an_uninterrupted_run(finished_run, tmp_path):
    out = tmp_path / "interrupted"
    assert train_cli.main(tiny_args(out, stop_after_chunks=1)) == {"stopped_at": 2}
    assert not (out / "results_test.json").exists()
    # A kill after the metrics of update 3 were written but before its checkpoint: the
    # resumed run must drop that row and redo update 3.
    stale = dict(runs.read_rows(out / "metrics")[-1], update=3)
    runs.append_rows(out / "metrics", [stale])
    # The run folder alone says what to resume (method, preset and seed are not repeated).
    train_cli.main(train_cli.Args(out=out, resume=True, progress=False))

    for name in ("metrics.csv", "metrics.jsonl", "validation.jsonl", "validation.csv", "results_test.json"):
        assert (out / name).read_text() == (finished_run / name).read_text(), name
    for folder in ("checkpoints", "best"):
        step, steps, resumed = restore_latest(out, folder)
        ref_step, ref_steps, reference = restore_latest(finished_run, folder)
        assert (step, steps) == (ref_step, ref_steps)
        H.assert_trees_bitwise_equal(resumed, reference)


def test_overwrite_replaces_a_run_and_same_seed_gives_the_same_run(finished_run, tmp_path):
    out = tmp_path / "copy"
    shutil.copytree(finished_run, out)
    (out / "stray.txt").write_text("from the old run")
    train_cli.main(tiny_args(out, overwrite=True))
    assert not (out / "stray.txt").exists()
    assert (out / "metrics.csv").read_text() == (finished_run / "metrics.csv").read_text()
    assert (out / "results_test.json").read_text() == (finished_run / "results_test.json").read_text()


def test_existing_folders_are_never_overwritten_without_a_flag(finished_run, tmp_path, capsys):
    before = snapshot(finished_run)
    line = cli_error(train_cli.cli, ["--preset", "tiny", "--out", finished_run], capsys)
    assert "already exists" in line and "--resume" in line and "--overwrite" in line
    # A bad value with --overwrite fails before anything is deleted.
    line = cli_error(train_cli.cli, ["--preset", "tiny", "--out", finished_run, "--overwrite", "--num-lanes", "0"], capsys)
    assert "num_lanes must be >= 1" in line
    assert snapshot(finished_run) == before

    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "thesis.tex").write_text("months of work")
    for flags in ([], ["--overwrite"]):
        line = cli_error(train_cli.cli, ["--preset", "tiny", "--out", notes, *flags], capsys)
    assert "not a run folder" in line and "refusing to delete" in line
    line = cli_error(train_cli.cli, ["--out", notes, "--resume"], capsys)
    assert "not a run folder" in line
    assert snapshot(notes) == {"thesis.tex": b"months of work"}


def test_non_finite_loss_stops_training_naming_the_update_and_keeps_the_last_good_checkpoint(tmp_path, capsys):
    out = tmp_path / "diverging"
    train_cli.main(tiny_args(out, stop_after_chunks=1))
    # Poison the rewards from update 3 on (same shapes and types: the compiled chunk is
    # reused): every loss of the second chunk is NaN.
    trainer = H.cached_trainer(run_config(out))
    good = trainer.env_params
    trainer.env_params = good.replace(step_penalty=float("nan"))
    capsys.readouterr()
    try:
        with pytest.raises(SystemExit) as exc:
            train_cli.main(train_cli.Args(out=out, resume=True, progress=False))
    finally:
        trainer.env_params = good
    assert exc.value.code == 1
    message = capsys.readouterr().err.strip().splitlines()[-1]
    assert "non-finite loss at update 3" in message and "last good checkpoint (update 2)" in message
    step, steps, state = restore_latest(out)
    assert (step, steps) == (2, [2])
    H.assert_tree_finite(state)
    assert [r["update"] for r in runs.read_rows(out / "metrics")] == [1, 2]
    assert not (out / "results_test.json").exists()


# ---------------------------------------------------------------------- one-line errors
TRAIN_ERRORS = [
    (["--method", "bogus"], ["unknown method 'bogus'", "a3c, a3c+foresit, a3c+rnd, a3c+att, a3c+int, a3c+org"]),
    (["--method", "a3c+maml"], ["not implemented"]),
    (["--method", "a3c+org+foresit"], ["needs setup 'org'"]),
    (["--setup", "thor"], ["setup must be one of"]),
    (["--preset", "huge"], ["unknown preset 'huge'", "tiny, quick, paper"]),
    (["--num-lanes", "0"], ["num_lanes must be >= 1"]),
    (["--num-updates", "0"], ["num_updates must be >= 1"]),
    (["--learning-rate", "-0.001"], ["learning_rate must be > 0"]),
    (["--learning-rate", "0"], ["learning_rate must be > 0"]),
    (["--chunk-updates", "0"], ["chunk_updates must be >= 1"]),
    (["--val-episodes-per-room", "0"], ["val_episodes_per_room must be >= 1"]),
    (["--resume"], ["not a run folder"]),
    (["--resume", "--overwrite"], ["exclude each other"]),
]


@pytest.mark.parametrize("argv, expected", TRAIN_ERRORS, ids=[" ".join(a) for a, _ in TRAIN_ERRORS])
def test_train_rejects_bad_input_in_one_line(argv, expected, tmp_path, capsys):
    out = tmp_path / "new_run"
    line = cli_error(train_cli.cli, ["--preset", "tiny", "--out", out, *argv], capsys)
    for text in expected:
        assert text in line
    assert not out.exists()  # nothing was created for a command that failed


def test_buffer_size_below_one_is_refused():
    """(Not a CLI flag; a preset override or a Config.)"""
    with pytest.raises(ValueError, match="buffer_size must be >= 1"):
        presets.preset("tiny", "a3c+foresit", buffer_size=0)


def test_evaluate_rejects_bad_input_in_one_line(finished_run, tmp_path, capsys):
    nothing = tmp_path / "nothing"
    nothing.mkdir()
    assert "not a run folder" in cli_error(evaluate_cli.cli, ["--run", nothing], capsys)
    assert "--split must be val or test" in cli_error(evaluate_cli.cli, ["--run", finished_run, "--split", "train"], capsys)
    for n in ("0", "-3"):
        line = cli_error(evaluate_cli.cli, ["--run", finished_run, "--episodes-per-room", n], capsys)
        assert "--episodes-per-room must be >= 1" in line
    # train wrote results_test.json: evaluating the same model again needs --overwrite.
    assert "--overwrite" in cli_error(evaluate_cli.cli, ["--run", finished_run], capsys)


def test_sweep_rejects_bad_input_in_one_line(tmp_path, capsys):
    out = tmp_path / "sweep"
    base = ["--preset", "tiny", "--out", out]
    assert "--seeds must be >= 1" in cli_error(sweep.cli, [*base, "--seeds", "0"], capsys)
    assert "unknown method 'bogus'" in cli_error(sweep.cli, [*base, "--methods", "a3c", "bogus"], capsys)
    assert "valid presets" in cli_error(sweep.cli, ["--preset", "huge", "--out", out], capsys)
    assert ">= 1" in cli_error(sweep.cli, [*base, "--test-episodes-per-room", "0"], capsys)
    assert not out.exists()
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "keep.txt").write_text("x")
    assert "refusing to delete" in cli_error(sweep.cli, [*base[:2], "--out", notes, "--overwrite"], capsys)
    assert (notes / "keep.txt").exists()


def test_bad_method_from_the_shell_is_one_line_without_traceback(tmp_path):
    """The real command line (a fresh interpreter); it fails before anything compiles."""
    out = tmp_path / "x"
    proc = subprocess.run(
        [sys.executable, "-m", "experiments.train", "--method", "bogus", "--out", str(out)],
        cwd=REPO, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert lines == [lines[0]] and lines[0].startswith("error: unknown method 'bogus'"), proc.stderr
    assert "valid methods: a3c, a3c+foresit" in lines[0]
    assert not out.exists()


# ---------------------------------------------------------------------- evaluate CLI
def test_evaluate_cli_reproduces_the_test_results_of_training(finished_run, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(finished_run, out)
    trained = json.loads((out / "results_test.json").read_text())
    # The model selected on validation, loaded from best/, on the same episodes (train
    # evaluates the test split with PRNGKey(seed + 10_000)).
    results = evaluate_cli.main(evaluate_cli.Args(run=out, seed=SEED + 10_000, overwrite=True))
    np.testing.assert_equal(results, trained["results"])  # (NaN == NaN here)
    written = json.loads((out / "results_test.json").read_text())
    np.testing.assert_equal(written["results"], trained["results"])
    assert written["which"] == "best"
    # The last checkpoint goes to its own files and leaves the others alone.
    last = evaluate_cli.main(evaluate_cli.Args(run=out, which="last", split="val", episodes_per_room=2))
    assert set(last) == {"bathroom", "overall"} and last["overall"]["episodes"] == 2
    assert (out / "results_val_last.json").exists() and (out / "results_val_last.md").exists()


# ---------------------------------------------------------------------- the README
README = (REPO / "README.md").read_text()
BLOCKS = re.findall(r"```(\w+)\n(.*?)```", README, flags=re.S)
CLI_MODULES = {"experiments.train": train_cli, "experiments.evaluate": evaluate_cli, "experiments.sweep": sweep}
# Benchmarks the README documents: their flags must parse (they run in their own tests or
# take minutes by design).
BENCH_ARGS = {
    "experiments.bench_train": lambda: importlib.import_module("experiments.bench_train").BenchConfig,
    "experiments.bench_learning": lambda: importlib.import_module("experiments.bench_learning").BenchLearning,
}


def readme_commands() -> list[list[str]]:
    """Every `python -m experiments.X ...` of the README's bash blocks, as argv lists."""
    commands = []
    for lang, body in BLOCKS:
        if lang != "bash":
            continue
        for line in body.splitlines():
            for part in line.split("&&"):
                words = shlex.split(part, comments=True)
                if words[:2] == ["python", "-m"] and words[2].startswith("experiments."):
                    commands.append(words[2:])
    return commands


def test_readme_commands_parse():
    """Every documented experiments command (code blocks and inline) names a module that
    exists, and the flags of the train/evaluate/sweep ones are accepted."""
    commands = readme_commands()
    assert {c[0] for c in commands} >= set(CLI_MODULES)
    for module, *argv in commands:
        parser = CLI_MODULES[module].Args if module in CLI_MODULES else BENCH_ARGS[module]()
        args = tyro.cli(parser, args=argv)
        assert dataclasses.is_dataclass(args)
    for module in set(re.findall(r"python -m (experiments\.\w+)", README)):
        assert importlib.util.find_spec(module) is not None, module


def tiny_argv(module: str, argv: list[str], folder: Path) -> list[str]:
    """The same command at a tiny size: preset tiny, run folders under `folder`."""
    out, flag = [], None
    for word in argv:
        if flag == "--preset":
            word = "tiny"
        elif flag in ("--out", "--run"):
            word = str(folder / word)
        out.append(word)
        flag = word if word.startswith("--") else None
    if "progress" in {f.name for f in dataclasses.fields(CLI_MODULES[module].Args)}:
        out.append("--no-progress")
    return out


@pytest.mark.timeout(600)
def test_readme_commands_run_at_a_tiny_size(tmp_path, capsys):
    for module, *argv in readme_commands():
        if module not in CLI_MODULES:  # benchmarks: parsed above, run by their own tests
            continue
        args = tyro.cli(CLI_MODULES[module].Args, args=tiny_argv(module, argv, tmp_path))
        CLI_MODULES[module].main(args)
    # What each command promises to write.
    runs_written = [p for p in (tmp_path / "runs").iterdir() if runs.is_run(p)]
    assert runs_written
    for run in runs_written:
        assert (run / "results_test.md").exists() and (run / "learning_curve.png").exists()
    sweeps = [p for p in (tmp_path / "runs").iterdir() if (p / "sweep.json").exists()]
    for folder in sweeps:
        assert (folder / "table1.md").exists() and (folder / "learning_curves.png").exists()
        rows = list(csv_rows(folder / "table1.csv"))
        assert [r["method"] for r in rows] == list(json.loads((folder / "sweep.json").read_text())["methods"])


def csv_rows(path: Path):
    import csv

    with open(path) as f:
        yield from csv.DictReader(f)


def test_readme_python_blocks_run_at_a_tiny_size():
    """The README's Python examples, executed with smaller sizes substituted (bathrooms
    only, 2 lanes, 1 update, a small network): the API calls are the documented ones."""
    python_blocks = [body for lang, body in BLOCKS if lang == "python"]
    assert len(python_blocks) >= 2
    small = ('num_lanes=2, num_updates=1, room_types=("bathroom",), hidden_size=16, attention_size=16, '
             "value_hidden=16, imagination_layer_sizes=(16, 8, 4, 8, 16, 16)")  # fmt: skip
    for body in python_blocks:
        code = body.replace('split="train")', 'split="train", room_types=("bathroom",))')
        code = re.sub(r"num_lanes=\d+, num_updates=\d+", small, code)
        assert code != body, "nothing to shrink in this README block: update the substitutions"
        namespace: dict = {}
        exec(compile(code, "README.md", "exec"), namespace)  # noqa: S102
        if "make_train" in body:
            state, metrics = namespace["state"], namespace["metrics"]
            seeds = int(re.search(r"PRNGKey\(0\), (\d+)\)", body).group(1))
            assert np.asarray(state.update).tolist() == [1] * seeds
            assert np.isfinite(np.asarray(metrics["losses/total_loss"])).all()
        if "envs.make" in body:
            assert "obs" in namespace and "state" in namespace
