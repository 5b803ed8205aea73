"""experiments.running.paper_figures: the report's sampled results replay a sweep's sampled
test evaluation."""

import json

import pytest

from cli_helpers import SEED


# Cheap in-process CLI calls for every test of this module (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("cheap_experiments")


@pytest.mark.slow
def test_sampled_results_of_a_sweep_replay_its_sampled_test_evaluation(tiny_sweep):
    """paper_figures.sampled_results (the report's ORG rows with sampled actions): every finished
    seed's selected model on its own test episodes, actions sampled. a3c is evaluated
    sampled by its protocol, so these are the sweep's own test results again: the same
    models, episodes and keys."""
    from experiments.running import paper_figures

    sampled = paper_figures.sampled_results(tiny_sweep, ["a3c"])
    per_seed = json.loads((tiny_sweep / "methods" / "a3c" / "results.json").read_text())["results"]
    assert [r["seed"] for r in sampled["a3c"]] == [r["seed"] for r in per_seed] == [SEED, SEED + 1]
    for mine, theirs in zip(sampled["a3c"], per_seed):
        for col in ("SR", "SPL"):
            assert mine["overall"][col] == pytest.approx(theirs["selected"]["overall"][col], abs=1e-4), col
