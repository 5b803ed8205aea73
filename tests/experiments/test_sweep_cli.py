"""experiments.sweep, the program: seed i of a sweep is the run train makes with seed i, one-line
errors, seeds spread over two host devices, a killed sweep resumed, methods and seeds reused
from other sweeps, and Config flags saved, resumed and part of the protocol."""

import dataclasses
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

from cli_helpers import SEED, SWEEP_EPISODES, cli_error, csv_rows, sweep_args, validations
from experiments import evaluate as evaluate_cli
from experiments import sweep
from experiments import train as train_cli
from experiments import errors
from experiments.running import numerics, presets, selection, sweeps
from experiments import rundir
from experiments.running.run import COUNTS

REPO = Path(__file__).resolve().parents[2]

# Cheap in-process CLI calls for every test of this module (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("cheap_experiments")


@pytest.mark.slow
def test_sweep_seed_i_is_the_run_train_makes_with_seed_i(tiny_sweep, tmp_path):
    """The same protocol in both: seed i of a sweep starts from train --seed i's key,
    validates on its episodes after each chunk, selects the same update and tests on the
    same episodes (equal up to the vmapped program's float rounding, which does not flip
    an outcome at this size); the last model is tested too.  (Enough episodes that other
    keys give other numbers: with a test key or a training key off by one, this fails.)"""
    out, episodes = tiny_sweep, SWEEP_EPISODES
    per_seed = json.loads((out / "results_per_seed.json").read_text())["a3c+foresit"]
    assert [r["seed"] for r in per_seed] == [SEED, SEED + 1]
    trained = [tmp_path / f"train{i}" for i in range(2)]
    for i, run in enumerate(trained):
        train_cli.main(
            train_cli.Args(method="a3c+foresit", preset="tiny", seed=SEED + i, out=run, progress=False, **episodes)
        )
    for r, run in zip(per_seed, trained):
        mine = json.loads((run / "results_test.json").read_text())
        assert r["selected_update"] == mine["selected_update"]
        rows = list(rundir.read_rows(run / "metrics"))
        curve = [row["charts/success_rate"] for row in rows]
        np.testing.assert_allclose(r["training_success_rate"], curve, atol=1e-6)  # the same episodes were trained on
        for name in COUNTS:  # the experience counted is train's, update by update
            assert r["counts"][name] == pytest.approx(sum(row[name] for row in rows)) and r["counts"][name] > 0
        validation = validations(run)
        assert [v["update"] for v in r["validation"]] == [v["update"] for v in validation] == [2, 4]
        np.testing.assert_allclose([v["SR"] for v in r["validation"]], [v["SR"] for v in validation])
        for col in ("SR", "SPL", "episodes"):
            assert r["selected"]["overall"][col] == pytest.approx(mine["results"]["overall"][col], abs=1e-3)
        last = evaluate_cli.main(evaluate_cli.Args(run=run, which="last", overwrite=True))  # on train's test episodes
        for col in ("SR", "SPL"):
            assert r["last"]["overall"][col] == pytest.approx(last["overall"][col], abs=1e-3)
    table = next(csv_rows(out / "table1.csv"))
    assert float(table["SR mean"]) == pytest.approx(np.mean([r["selected"]["overall"]["SR"] for r in per_seed]))
    md = (out / "table1.md").read_text()
    assert "Model selection" in md and f"{SEED}: " in md and f"(update {per_seed[0]['selected_update']})" in md
    assert "### a3c+foresit - a3c, paired per bucket" in md


def test_sweep_rejects_bad_input_in_one_line(tmp_path, capsys):
    out = tmp_path / "sweep"
    base = ["--preset", "tiny", "--out", out]
    assert "--seeds must be >= 1" in cli_error(sweep.cli, [*base, "--seeds", "0"], capsys)
    assert "a3c more than once" in cli_error(sweep.cli, [*base, "--methods", "a3c", "a3c+critic", "a3c"], capsys)
    assert "2**63-1" in cli_error(sweep.cli, [*base, "--seed", str(2**63 - 2), "--seeds", "3"], capsys)
    assert "unknown room type" in cli_error(sweep.cli, [*base, "--room-types", "garage"], capsys)
    assert not out.exists()
    assert "unknown method 'bogus'" in cli_error(sweep.cli, [*base, "--methods", "a3c", "bogus"], capsys)
    assert "valid presets" in cli_error(sweep.cli, ["--preset", "huge", "--out", out], capsys)
    assert ">= 1" in cli_error(sweep.cli, [*base, "--test-episodes-per-room", "0"], capsys)
    assert not out.exists()
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "keep.txt").write_text("x")
    assert "refusing to delete" in cli_error(sweep.cli, [*base[:2], "--out", notes, "--overwrite"], capsys)
    assert (notes / "keep.txt").exists()


@pytest.mark.slow
def test_a_sweep_spread_over_two_host_devices_equals_the_one_device_sweep(tiny_sweep, tmp_path):
    """The seed axis sharded over 2 forced host devices (a fresh interpreter: the flag
    must precede jax's start): the same selections, validation and test results, and
    training curves equal to float rounding.  In the same interpreter, a3c+maml's sharded
    sweep program lowers (with nn.Conv in L_phi, partitioning its second-order
    convolutions raised NotImplementedError).  Its checkpoint, saved from the 2 devices, is
    read back onto one device, there and in this process (before, it came back spread over
    both there, and failed with orbax's "Topology mismatch" in a 1-device process)."""
    out = tmp_path / "two_devices"
    on_one_device = (
        "assert {d for x in jax.tree.leaves(read[2:]) for d in x.sharding.device_set} == {jax.local_devices()[0]}"
    )
    code = (
        "import sys, pytest, jax; sys.path.insert(0, 'tests'); import train_helpers as H\n"
        "assert jax.device_count() == 2, jax.devices()\n"
        "H.patch_for_experiments(pytest.MonkeyPatch())\n"
        "import dataclasses; from pathlib import Path; from experiments import sweep; from experiments.running import sweeps; import cli_helpers as T\n"
        f"sweep.main(dataclasses.replace(T.sweep_args(Path({str(out)!r})), methods=('a3c',)))\n"
        f"read = sweeps.load_method('a3c', T.sweep_args(Path({str(out)!r})), Path({str(out / 'methods' / 'a3c')!r}))\n"
        f"{on_one_device}\n"
        "from experiments.running import devices; from experiments.running.presets import preset; from foresit_jax.train import make_trainer\n"
        "trainer = make_trainer(preset('tiny', 'a3c+maml')[0])\n"
        "states = jax.vmap(trainer.init)(jax.random.split(jax.random.PRNGKey(0), 2))\n"
        "trainer.run_seeds.lower(devices.shard_seeds(states, devices.seed_mesh(2)), trainer.env_params, 2)\n"
    )  # one method of the two: its numbers do not depend on the others
    env = {**os.environ, "XLA_FLAGS": "--xla_force_host_platform_device_count=2"}
    proc = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    read = sweeps.load_method("a3c", sweep_args(out), out / "methods" / "a3c")
    assert {d for x in jax.tree.leaves(read[2:]) for d in x.sharding.device_set} == {jax.local_devices()[0]}
    one, two = (json.loads((d / "results_per_seed.json").read_text()) for d in (tiny_sweep, out))
    assert list(two) == ["a3c"]
    for a, b in zip(one["a3c"], two["a3c"], strict=True):
        assert (a["seed"], a["selected_update"]) == (b["seed"], b["selected_update"])
        np.testing.assert_allclose(a["training_success_rate"], b["training_success_rate"], atol=1e-6)
        for key in ("selected", "last"):
            for col in ("SR", "SPL", "episodes"):
                assert a[key]["overall"][col] == pytest.approx(b[key]["overall"][col], abs=1e-3)
        assert [v["SR"] for v in a["validation"]] == pytest.approx([v["SR"] for v in b["validation"]])


@pytest.mark.slow
def test_a_killed_sweep_resumes_where_it_stopped_and_ends_with_the_same_numbers(tiny_sweep, tmp_path, capsys):
    out = tmp_path / "killed"
    # 2 chunks per method: a3c finishes, a3c+foresit stops after its first chunk.
    assert sweep.main(dataclasses.replace(sweep_args(out), stop_after_chunks=3)) is None
    assert "continue with --resume" in capsys.readouterr().out
    finished, started = out / "methods" / "a3c", out / "methods" / "a3c+foresit"
    assert (finished / "results.json").exists() and not (started / "results.json").exists()
    assert json.loads((started / "progress.json").read_text())["done"] == 2
    kept = (finished / "results.json").stat().st_mtime_ns
    # (How an arm's run resumes from each state a kill leaves: tests/experiments/test_run.py.)
    # A method validated under another selection protocol is not continued under this one.
    progress = json.loads((started / "progress.json").read_text())
    assert progress["selection_protocol"] == selection.PROTOCOL_VERSION
    (started / "progress.json").write_text(json.dumps({**progress, "selection_protocol": 1}))
    line = cli_error(sweep.cli, ["--out", out, "--resume"], capsys)
    assert "a3c+foresit in" in line and "validated under selection protocol 1" in line
    (started / "progress.json").write_text(json.dumps(progress))
    # --resume takes the arguments the sweep was started with, and refuses others.
    assert "drop --seeds 9 (started with 2)" in cli_error(sweep.cli, ["--out", out, "--resume", "--seeds", "9"], capsys)
    sweep.cli(["--out", str(out), "--resume", "--no-progress"])
    assert (finished / "results.json").stat().st_mtime_ns == kept  # a finished method is not run again
    for name in ("results_per_seed.json", "table1.csv", "table1.md"):
        assert (out / name).read_text() == (tiny_sweep / name).read_text(), name


@pytest.mark.slow
def test_a_sweep_copies_the_methods_another_sweep_finished_instead_of_training_them(tiny_sweep, tmp_path, capsys):
    out = tmp_path / "combined"
    # A budget of 0 chunks: nothing may train, both methods must come from tiny_sweep.
    assert sweep.main(dataclasses.replace(sweep_args(out), reuse=(tiny_sweep,), stop_after_chunks=0)) is not None
    assert "a3c+foresit: finished in" in capsys.readouterr().out
    for name in ("results_per_seed.json", "table1.csv", "table1.md"):
        assert (out / name).read_text() == (tiny_sweep / name).read_text(), name
    assert not list((out / "methods").glob(".*"))  # no partial copy left behind
    # Refused in one line: the sweep itself, a folder that is no sweep, another protocol.
    line = cli_error(sweep.cli, ["--out", out, "--overwrite", "--reuse", out], capsys)
    assert "the sweep being written" in line and (out / "table1.md").exists()
    assert "not a sweep folder" in cli_error(sweep.cli, ["--out", tmp_path / "x", "--reuse", tmp_path], capsys)
    argv = ["--preset", "tiny", "--val-episodes-per-room", "5", "--out", tmp_path / "x", "--reuse", tiny_sweep]
    line = cli_error(sweep.cli, argv, capsys)
    assert "another protocol" in line and "--val-episodes-per-room 12 there, 5 here" in line
    # A method selected by an earlier version of experiments.running.selection (no version recorded).
    old = tmp_path / "old"
    shutil.copytree(tiny_sweep, old)
    done = old / "methods" / "a3c" / "results.json"
    done.write_text(json.dumps({k: v for k, v in json.loads(done.read_text()).items() if k != "selection_protocol"}))
    with pytest.raises(errors.UserError, match=r"its a3c was selected by another protocol \(version 1"):
        sweep.main(dataclasses.replace(sweep_args(tmp_path / "x"), reuse=(old,)))
    assert not (tmp_path / "x").exists()
    # A method trained on another platform is combined, and the table says which pair mixes platforms.
    moved = tmp_path / "moved"
    shutil.copytree(tiny_sweep, moved)
    done = moved / "methods" / "a3c+foresit" / "results.json"
    finished = json.loads(done.read_text())
    elsewhere = [{"from_update": 0, "platform": {**numerics.fingerprint(), "jax": "0.0.1"}}]
    for r in finished["results"]:
        assert r["numerics"] == [{"from_update": 0, "platform": numerics.fingerprint()}]
        r["numerics"] = elsewhere
    done.write_text(json.dumps(finished))
    sweep.main(dataclasses.replace(sweep_args(tmp_path / "mixed"), reuse=(moved,), stop_after_chunks=0))
    md = (tmp_path / "mixed" / "table1.md").read_text()
    assert f"- {numerics.describe(elsewhere[0]['platform'])}: a3c+foresit\n" in md
    assert "different platforms (or a run on several): a3c and a3c+foresit." in md
    assert (
        f"Every method was trained on {numerics.describe(numerics.fingerprint())}."
        in (tiny_sweep / "table1.md").read_text()
    )


@pytest.mark.slow
def test_a_sweep_assembles_a_method_from_the_seeds_other_sweeps_finished(tiny_sweep, tmp_path, capsys):
    """Seeds S and S+1 of tiny_sweep and seed S+2 of a one-seed sweep (`--seed S+2
    --seeds 1`) make a three-seed sweep with nothing trained: each seed's results are its
    source's, and the assembled checkpoint holds each seed's own states and selected model
    (what the paper's figures load); a seed no source has makes every seed train."""
    extra = tmp_path / "third"
    sweep.main(dataclasses.replace(sweep_args(extra), methods=("a3c",), seed=SEED + 2, seeds=1))
    capsys.readouterr()
    three = dataclasses.replace(sweep_args(tmp_path / "three"), methods=("a3c",), seeds=3, reuse=(tiny_sweep, extra))
    assert sweep.main(dataclasses.replace(three, stop_after_chunks=0)) is not None  # a budget of 0: nothing trains
    assert f"a3c: assembled (seeds {SEED}-{SEED + 1} from {tiny_sweep}; seeds {SEED + 2} from {extra})" in (
        capsys.readouterr().out
    )
    per_seed = json.loads((three.out / "results_per_seed.json").read_text())["a3c"]
    sources = [json.loads((d / "results_per_seed.json").read_text())["a3c"] for d in (tiny_sweep, extra)]
    assert per_seed == sources[0] + sources[1]
    done = json.loads((three.out / "methods" / "a3c" / "results.json").read_text())
    assert done["curves"] == [r["training_success_rate"] for r in per_seed]
    assert done["assembled_from"] == {
        str(SEED): str(tiny_sweep / "methods" / "a3c"),
        str(SEED + 1): str(tiny_sweep / "methods" / "a3c"),
        str(SEED + 2): str(extra / "methods" / "a3c"),
    }
    md = (three.out / "table1.md").read_text()
    assert (
        f"- a3c: seeds {SEED}-{SEED + 1} from {tiny_sweep / 'methods' / 'a3c'}; "
        f"seeds {SEED + 2} from {extra / 'methods' / 'a3c'}\n"
    ) in md
    assert "combined" not in (tiny_sweep / "table1.md").read_text()
    table = next(csv_rows(three.out / "table1.csv"))
    assert table["seeds"] == "3"
    assert float(table["SR mean"]) == pytest.approx(np.mean([r["selected"]["overall"]["SR"] for r in per_seed]))
    loaded = [sweeps.load_method("a3c", three, d / "methods" / "a3c")[2:] for d in (three.out, tiny_sweep, extra)]
    assert jax.tree.structure(loaded[0]) == jax.tree.structure(loaded[1])
    for got, first, second in zip(*(jax.tree.leaves(x) for x in loaded), strict=True):
        np.testing.assert_array_equal(got, np.concatenate([first, second]))
    # A subset of a source's seeds: seed S+1 alone is taken from tiny_sweep (not copied whole).
    one = dataclasses.replace(
        sweep_args(tmp_path / "one"), methods=("a3c",), seed=SEED + 1, seeds=1, reuse=(tiny_sweep,), stop_after_chunks=0
    )
    assert sweep.main(one) is not None
    assert json.loads((one.out / "results_per_seed.json").read_text())["a3c"] == sources[0][1:]
    # Seed S+3 is in no source: all four seeds would train (a budget of 0 stops it), and it says why.
    four = dataclasses.replace(three, out=tmp_path / "four", seeds=4, stop_after_chunks=0)
    assert sweep.main(four) is None
    out = capsys.readouterr().out
    assert f"a3c: seeds {SEED}-{SEED + 2} are finished in --reuse, but not seeds {SEED + 3}, so all 4 seeds" in out
    assert not (four.out / "methods" / "a3c" / "results.json").exists()
    for d, before in zip((tiny_sweep, extra), sources):  # the sources are only read
        assert json.loads((d / "results_per_seed.json").read_text())["a3c"] == before


@pytest.mark.slow
def test_sweep_config_flags_are_saved_resumed_and_part_of_the_protocol(tmp_path, capsys):
    base = sweep.Args(methods=("a3c",), seeds=1, preset="tiny", seed=SEED, progress=False, **SWEEP_EPISODES)
    first = dataclasses.replace(base, out=tmp_path / "lr", config=presets.SweepConfigFields(learning_rate=3e-4))
    assert sweep.main(dataclasses.replace(first, stop_after_chunks=1)) is None
    line = cli_error(sweep.cli, ["--out", first.out, "--resume", "--learning-rate", "1e-3"], capsys)
    assert "--learning-rate 0.001 (started with 0.0003)" in line
    sweep.cli(["--out", str(first.out), "--resume", "--no-progress"])
    config, *_ = sweeps.load_method("a3c", first, first.out / "methods" / "a3c")
    assert config.learning_rate == 3e-4
    # Reuse takes only the sweeps of the same Config fields.
    other = dataclasses.replace(base, out=tmp_path / "other", reuse=(first.out,))
    line = cli_error(
        sweep.cli,
        [
            "--methods",
            "a3c",
            "--seeds",
            "1",
            "--preset",
            "tiny",
            "--seed",
            SEED,
            "--out",
            other.out,
            "--reuse",
            first.out,
        ],
        capsys,
    )
    assert "run with another protocol" in line and "--config" in line
    # A sweep saved before it had Config fields reads back with none set.
    saved = rundir.read_json(first.out / "sweep.json")
    del saved["config"]
    assert rundir.args_from_saved(sweep.Args, saved).config == presets.SweepConfigFields()
