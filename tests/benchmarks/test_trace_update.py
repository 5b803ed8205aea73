"""benchmarks.trace_update: the training path a reader crosses, and the lowered programs'
hashes a refactor is checked with. Lowering only (nothing compiles or runs)."""

import dataclasses

import jax
import pytest

from benchmarks import trace_update
from experiments.running.presets import preset
from foresit_jax.train import make_trainer


@pytest.mark.slow
def test_the_path_of_an_update_and_hashes_that_tell_programs_apart(capsys):
    report = trace_update.main(trace_update.Args(methods=("a3c",)))["a3c"]
    files = report["files"]
    # The files every a3c update goes through; not the ones only other methods use.
    assert {"train.py", "rollout.py", "networks.py", "imagination.py", "lstm.py"} <= set(files)
    assert "maml.py" not in files and "org.py" not in files
    assert all(functions >= 1 and lines >= functions for functions, lines in files.values())
    out = capsys.readouterr().out
    assert f"crosses {sum(f for f, _ in files.values())} functions" in out
    # The same program hashes the same; one constant changed (gamma) hashes otherwise.
    config, _ = preset("tiny", "a3c")
    trainer = make_trainer(config)
    state = trainer.init(jax.random.PRNGKey(0))
    assert trace_update.program_hashes(trainer, state) == report["hashes"]
    other = make_trainer(dataclasses.replace(config, gamma=0.9))
    hashes = trace_update.program_hashes(other, other.init(jax.random.PRNGKey(0)))
    assert hashes["train"] != report["hashes"]["train"] and hashes["evaluate"] == report["hashes"]["evaluate"]


@pytest.mark.slow
def test_the_path_from_the_cli_to_the_optimiser():
    """`--cli-path`: the project files whose functions run from `python -m experiments.train`'s
    entry to the first `optax.apply_updates`, in the order entered, the reader's path (the
    call chain to the optimiser, then the update's body; docs/design.md walks it), and the
    Config's sources besides (where a Config is made, and what its making enters), for
    a3c+foresit (issue 70's count)."""
    path = trace_update.files_from_cli("a3c+foresit", "tiny")
    entered, reader, config = path.entered, path.reader, path.config
    assert len(entered) == len(set(entered)) and len(reader) == len(set(reader))
    assert {
        "experiments/train.py",
        "experiments/running/run.py",
        "foresit_jax/config.py",
        "foresit_jax/train.py",
        "foresit_jax/rollout.py",
        "foresit_jax/networks.py",
        "envs/gridnav.py",
    } <= set(entered)
    assert (
        "foresit_jax/maml.py" not in entered and "foresit_jax/policy.py" not in entered
    )  # neither runs for a3c+foresit
    assert set(reader) <= set(entered)
    # the chain first (the command, its run, the Trainer), then the update's body
    assert reader[:3] == ["experiments/errors.py", "experiments/train.py", "experiments/running/run.py"]
    assert reader.index("foresit_jax/train.py") < reader.index("foresit_jax/rollout.py")
    assert {"foresit_jax/lstm.py", "foresit_jax/imagination.py", "envs/gridnav.py", "envs/dynamics.py"} <= set(reader)
    # setup is not what one update is: the run folder's helpers and the scene banks are run, not followed
    assert not {"experiments/rundir.py", "envs/bank.py"} & set(reader)
    # what the Config says: the preset, the Config's defaults and checks, the method's parser
    assert {"experiments/running/presets.py", "foresit_jax/config.py", "foresit_jax/methods.py"} <= set(config)
    assert not set(config) & set(reader) and path.to_read == reader + config
    assert len(reader) <= 12 and len(path.to_read) <= 15  # 15 at 4b5e70b; issue 70's target is 12 (docs/design.md)


# ForeSIT's acting step, through the lax.cond branch that renews i_tau: step, agent_step,
# at_step, renewed, imagine, add_imagination_noise (0.3.0's docs counted 4, leaving the branch
# out; 0.4.0 moved the steps after agent_step into imagination.py and counts its calls too:
# 6, where rollout.py's alone gave 5 and 0.3's code, counted so, also gives 6).
MAX_ACTING_DEPTH = 6


@pytest.mark.slow  # the trace hook slows lowering to about 13 s
def test_an_acting_step_is_counted_through_its_cond_branch():
    config, _ = preset("tiny", "a3c+foresit")
    trainer = make_trainer(config)
    chain = trace_update.acting_depth(trainer, trainer.init(jax.random.PRNGKey(0)))
    assert chain == ["step", "agent_step", "at_step", "renewed", "imagine", "add_imagination_noise"]
    assert len(chain) <= MAX_ACTING_DEPTH
