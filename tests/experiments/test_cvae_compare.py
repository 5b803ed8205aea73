"""experiments.cvae_compare: the C-VAE comparison from a run folder."""

import json
import shutil

import numpy as np
import pytest

from cli_helpers import cli_error
from experiments.reporting import cvae_comparison


# Cheap in-process CLI calls for every test of this module (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("cheap_experiments")


@pytest.mark.slow
def test_cvae_comparison_on_a_run(finished_run, tmp_path, capsys):
    """The C-VAE comparison from a run folder: items of the run's successful episodes, both
    f_w trained, the files written once (never replaced without --overwrite)."""
    from experiments import cvae_compare

    out = tmp_path / "run"
    shutil.copytree(finished_run, out)
    result = cvae_compare.main(cvae_compare.Args(run=out, windows=40, epochs=3))
    assert result["items"] >= cvae_comparison.MIN_ITEMS and result["update"] == 4 and result["latent_size"] == 8
    assert np.isfinite(result["direct"]["loss"]) and np.isfinite(result["cvae_latent"]["loss"])
    assert json.loads((out / "cvae_comparison.json").read_text())["items"] == result["items"]
    assert "C-VAE's latent mean" in (out / "cvae_comparison.md").read_text()
    assert "pass --overwrite" in cli_error(cvae_compare.cli, ["--run", out], capsys)
    assert "raise --windows" in cli_error(cvae_compare.cli, ["--run", out, "--windows", "1", "--overwrite"], capsys)
