"""docs/results.md's PPO reference row is what its files give (docs/data/reference_ppo_*.json;
the program itself: tests/benchmarks/test_reference_ppo.py)."""

import json
from pathlib import Path

import numpy as np

from benchmarks import reference_ppo as R

REPO = Path(__file__).resolve().parents[2]


def test_results_md_quotes_the_reference_row(tmp_path):
    """docs/results.md's PPO reference row, recomputed from its files: the learning rate the
    validation chose, the test SR and SPL over seeds 0-4, and the pair against a3c at its
    validated 1e-3 (docs/data/fair_tune.tar.xz) on the same test episodes."""
    import study_data

    from experiments.reporting import stats

    results = (REPO / "docs" / "results.md").read_text()
    gpu = json.loads((REPO / "docs" / "data" / "reference_ppo_h200.json").read_text())
    cpu = json.loads((REPO / "docs" / "data" / "reference_ppo_epyc.json").read_text())
    assert gpu["seeds"] == [0, 1, 2, 3, 4] and gpu["ppo_config"]["TOTAL_TIMESTEPS"] == R.QUICK_FRAMES
    val = {float(lr): np.mean(v["val_sr"]) for lr, v in gpu["by_lr"].items()}
    assert max(val, key=val.get) == gpu["learning_rate"] == 2e-3
    assert (
        "| validation SR (chooses) | "
        + " | ".join(f"**{v:.1f}**" if lr == 2e-3 else f"{v:.1f}" for lr, v in sorted(val.items()))
        + " |"
        in results
    )
    cpu_val = {float(lr): np.mean(v["val_sr"]) for lr, v in cpu["by_lr"].items()}
    assert max(cpu_val, key=cpu_val.get) == max((lr for lr in val if lr in cpu_val), key=val.get)  # the same choice
    for name in ("sampled", "greedy"):
        sr, spl = stats.summary(gpu[name]["test_sr"]), stats.summary(gpu[name]["test_spl"])
        assert (
            f"| PPO, 2e-3, {name} actions | {sr['mean']:.1f} ± {sr['std']:.1f} | {spl['mean']:.1f} ± {spl['std']:.1f} |"
            in results
        )
    study_data.extract("fair_tune.tar.xz", tmp_path)
    a3c = json.loads((tmp_path / "tune" / "sweep" / "results_per_seed.json").read_text())["a3c@learning_rate=1e-3"]
    assert [r["seed"] for r in a3c] == gpu["seeds"]
    sr_pair = stats.paired([r["selected"]["overall"]["SR"] for r in a3c], gpu["sampled"]["test_sr"])
    spl_a3c = [r["selected"]["overall"]["SPL"] for r in a3c]
    spl_pair = stats.paired(spl_a3c, gpu["sampled"]["test_spl"])
    assert f"sampled PPO - a3c is {study_data.interval(sr_pair)} SR" in results
    mde = stats.minimum_detectable_effect(float(np.std(np.subtract(gpu["sampled"]["test_spl"], spl_a3c), ddof=1)), 5)
    assert f"On SPL, {study_data.interval(spl_pair)}: cannot tell (MDE {mde:.1f})" in results.replace("\n", " ")
