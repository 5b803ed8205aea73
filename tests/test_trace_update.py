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
    assert {"train.py", "agent.py", "networks.py", "losses.py", "lstm.py", "replay.py"} <= set(files)
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
