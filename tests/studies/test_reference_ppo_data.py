"""docs/reference_ppo.md's row: what its files record (docs/data/reference_ppo_*.json:
quick's frames, seeds 0-4, the rate validation chose), and that a3c, its pair, ran on the same
seeds (docs/data/fair_tune.tar.xz). The row's tables and the pair's words are generated blocks
(experiments/reporting/pages/results_md.py), held by the drift test
(tests/experiments/test_regenerate.py); the program itself: tests/benchmarks/test_reference_ppo.py."""

import json
from pathlib import Path

import numpy as np

from benchmarks import reference_ppo as R

REPO = Path(__file__).resolve().parents[2]


def test_the_reference_row_ran_on_quicks_frames_and_seeds():
    """Both files: seeds 0-4, quick's frames per seed, every rate's five validation SRs; the
    H200's recorded rate is the one its seeds' mean validation SR chooses."""
    for name in ("reference_ppo_h200.json", "reference_ppo_epyc.json"):
        run = json.loads((REPO / "docs" / "data" / name).read_text())
        assert run["seeds"] == [0, 1, 2, 3, 4] and run["ppo_config"]["TOTAL_TIMESTEPS"] == R.QUICK_FRAMES
        assert all(len(v["val_sr"]) == 5 for v in run["by_lr"].values())
    gpu = json.loads((REPO / "docs" / "data" / "reference_ppo_h200.json").read_text())
    val = {float(lr): np.mean(v["val_sr"]) for lr, v in gpu["by_lr"].items()}
    assert max(val, key=val.get) == gpu["learning_rate"] == 2e-3
    assert all(len(gpu[name][key]) == 5 for name in ("sampled", "greedy") for key in ("test_sr", "test_spl"))


def test_a3c_the_pair_ran_on_the_same_seeds():
    """The pair sampled PPO - a3c is over the same seeds (and so the same test episodes): a3c at
    its validated rate in docs/data/fair_tune.tar.xz."""
    from experiments.reporting.registry import Archives

    gpu = json.loads((REPO / "docs" / "data" / "reference_ppo_h200.json").read_text())
    a3c = Archives().results("fair_tune.tar.xz", "a3c@learning_rate=1e-3")
    assert [r["seed"] for r in a3c] == gpu["seeds"]
