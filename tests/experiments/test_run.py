"""experiments.running.run: one run folder of N seeds, the format train (N = 1) and each arm
of a sweep write, and the one resume, extend and repair path both go through.

Each test runs once on one seed (the unvmapped program train runs) and once on two (the
vmapped program of a sweep's arm). The programs' own parts of a resume (train's metrics
rows, a sweep's arguments) are tested in test_train_cli.py, test_sweep_cli.py and
test_reliability.py.
"""

from __future__ import annotations

import functools
import shutil
from pathlib import Path

import jax
import numpy as np
import pytest

import train_helpers as H
from experiments.running import checkpoint, selection
from experiments import rundir
from experiments.running.presets import preset
from experiments.running.progress import progress_bar
from experiments.running.run import Run, initial_states, read

pytestmark = [pytest.mark.usefixtures("cheap_experiments"), pytest.mark.slow]

SEEDS = {"one seed": (1,), "two seeds": (1, 2)}


def make_run(folder: Path, seeds, num_updates: int = 6) -> Run:
    config, schedule = preset("tiny", "a3c", num_updates=num_updates)
    return Run(folder, config, schedule, seeds, "a3c", "tiny")


def train(run: Run, budget=None) -> bool:
    """`run` trained (within `budget` chunks), then tested when it finished; True if it did."""
    from foresit_jax.evaluate import Evaluator

    evaluator = Evaluator.for_config(run.config)
    finished = run.train(evaluator, progress_bar(run.config.num_updates, 0, False), [budget])
    if finished:
        run.test(evaluator)
    return finished


def final(run: Run):
    """The run's last training states and selected models, from its checkpoint."""
    return run.load()[1:]


@pytest.fixture(scope="module", params=list(SEEDS))
def whole(request, tmp_path_factory, cheap_experiments):
    """An uninterrupted run of 6 updates in chunks of 2: the reference."""
    run = make_run(tmp_path_factory.mktemp("run") / "whole", SEEDS[request.param])
    assert train(run)
    return run


def test_a_run_folder_reads_alone(whole):
    again = read(whole.folder)
    assert (again.config, again.schedule, again.seeds, again.label) == (
        whole.config,
        whole.schedule,
        whole.seeds,
        "a3c",
    )
    done = rundir.read_json(whole.folder / "results.json")
    assert done["updates"] == 6 and [r["seed"] for r in done["results"]] == list(whole.seeds)
    for r in done["results"]:
        assert [v["update"] for v in r["validation"]] == [2, 4, 6] and len(r["training_success_rate"]) == 6
        assert r["selected_update"] == max((v["SR"], v["update"]) for v in r["validation"])[1]  # the later on ties
        assert set(r["selected"]) == {"bathroom", "overall", "by_length"} and set(r["last"]) == set(r["selected"])
    states, best = final(whole)
    assert np.asarray(states.update).tolist() == [6] * len(whole.seeds)
    H.assert_tree_finite((states, best))


def test_one_seed_is_the_unvmapped_program_and_two_the_vmapped_one(whole):
    """train's numbers stay those of `jax.jit(trainer.run)` (a seed vmapped alone rounds
    differently); two seeds are `run_seeds`, the sweep's program."""
    trainer = H.cached_trainer(whole.config)
    if len(whole.seeds) == 1:
        run = jax.jit(trainer.run, static_argnums=2)
        state = trainer.init(selection.run_key(whole.seeds[0]))
        add_axis = functools.partial(jax.tree.map, lambda x: x[None])
    else:
        run = trainer.run_seeds
        state = initial_states(trainer, whole.seeds)[0]
        add_axis = lambda tree: tree  # noqa: E731
    for _ in range(3):  # the run's 3 chunks
        state, _ = run(state, trainer.env_params, 2)
    H.assert_trees_bitwise_equal(final(whole)[0], add_axis(state))


@pytest.mark.parametrize(
    "kill", ["after a chunk", "after a checkpoint, before progress.json", "flipped checkpoint", "truncated checkpoint"]
)
def test_a_killed_run_resumes_to_the_numbers_of_the_whole_one(whole, tmp_path, capsys, kill):
    run = make_run(tmp_path / "killed", whole.seeds)
    corrupt = kill.endswith(" checkpoint")
    assert not train(run, budget=2 if corrupt else 1)
    assert not (run.folder / "results.json").exists()
    if kill == "after a checkpoint, before progress.json":  # a newer checkpoint nothing records
        shutil.copytree(run.folder / "checkpoints" / "2", run.folder / "checkpoints" / "4")
    if corrupt:
        H.corrupt_checkpoint(run.folder / "checkpoints" / "4", kill.split()[0])
    capsys.readouterr()
    assert train(run)
    err = capsys.readouterr().err
    if corrupt:
        assert "is corrupt or truncated" in err and "continuing from update 2" in err, err
    for name in ("progress.json", "results.json"):
        assert (run.folder / name).read_text() == (whole.folder / name).read_text(), name
    H.assert_trees_bitwise_equal(final(run), final(whole))
    assert checkpoint.checkpoint_manager(run.folder / "checkpoints", 10).all_steps() == [4, 6]


def test_an_extended_run_ends_as_the_longer_one_and_keeps_its_shorter_results(whole, tmp_path, capsys):
    run = make_run(tmp_path / "extended", whole.seeds, num_updates=4)
    assert train(run)
    shorter = (run.folder / "results.json").read_text()
    with pytest.raises(Exception, match="would shorten"):
        run.extend(2)
    longer = run.extend(6)
    assert (run.folder / "results_4_updates.json").read_text() == shorter and not (run.folder / "results.json").exists()
    assert read(run.folder).config.num_updates == 6
    assert train(longer)
    for name in ("progress.json", "results.json"):
        assert (run.folder / name).read_text() == (whole.folder / name).read_text(), name
    H.assert_trees_bitwise_equal(final(longer), final(whole))
