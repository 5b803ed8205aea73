"""One update's loss, gradient and actions on fixed inputs are those saved in
tests/data/fixed_update.npz (`python -m benchmarks.fixed_update`, saved before issue 70's redesign):
the proof a redesign of the network's routes (issue 70) must pass, for a3c, a3c+foresit
(through head, encoder and mlp), a3c+critic, a3c+oracle, a3c+maml+foresit, a3c+org+foresit
and two privileged cues. Actions exactly; the loss and every gradient leaf's norm and
projections to test_example.py's tolerances (the fast and the plain forms of one
computation agree to float rounding)."""

from pathlib import Path

import numpy as np
import pytest

from benchmarks import fixed_update as F

SAVED = Path(__file__).resolve().parents[1] / "data" / "fixed_update.npz"
pytestmark = pytest.mark.slow  # ten programs compiled, about 2 minutes on a 2-core CPU


@pytest.fixture(scope="module")
def saved():
    with np.load(SAVED) as data:
        return {k: data[k] for k in data.files}


@pytest.mark.parametrize("name,method,setup,fields", F.ARMS, ids=[a[0] for a in F.ARMS])
def test_one_update_on_fixed_inputs_is_the_saved_one(name, method, setup, fields, saved):
    now = F.fixed_update(F.config_of(method, setup, fields))
    np.testing.assert_array_equal(now["actions"], saved[f"{name}|actions"])
    np.testing.assert_allclose(now["loss"], saved[f"{name}|loss"], rtol=1e-5, atol=1e-7)
    assert list(now["leaves"]) == list(saved[f"{name}|leaves"])
    digest, want = now["digest"], saved[f"{name}|digest"]
    scale = want[:, :1]  # each leaf's norm: the size of its projections
    assert np.all(np.abs(digest - want) <= 1e-4 * scale + 1e-9), np.max(np.abs(digest - want) / (scale + 1e-12))
    assert float(want[:, 0].max()) > 0  # a gradient that reaches the parameters


def test_the_digest_moves_when_one_entry_does():
    g = np.linspace(-1.0, 1.0, 64)
    d = F.directions("['params']['x']", g.size)
    moved = g.copy()
    moved[17] += 1e-2
    assert np.max(np.abs(d @ moved - d @ g)) > 1e-4 * np.linalg.norm(g)
    np.testing.assert_array_equal(F.directions("['params']['x']", 64), d)  # the same in every process
