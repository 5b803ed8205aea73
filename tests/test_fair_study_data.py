"""The fairness study's first sweep (issue 44: a3c, a3c+critic and a3c+foresit at Adam 3e-4,
seeds 0-4, quick): the figures docs/results.md and the README quote are those of its files,
kept without checkpoints as docs/data/fair_lr3e-4.tar.xz, recomputed here with
`experiments.compare` and `experiments.stats`."""

from __future__ import annotations

import tarfile
from pathlib import Path

import numpy as np
import pytest

from experiments import compare, runs, stats

REPO = Path(__file__).resolve().parents[1]
ARCHIVE = REPO / "docs" / "data" / "fair_lr3e-4.tar.xz"
ARMS = {"a3c": "a3c@learning_rate=3e-4", "a3c+critic": "a3c+critic@learning_rate=3e-4",
        "a3c+foresit": "a3c+foresit@learning_rate=3e-4"}  # fmt: skip
PAIRS = (("a3c", "a3c+foresit"), ("a3c", "a3c+critic"), ("a3c+critic", "a3c+foresit"))


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> dict[str, list[dict]]:
    folder = tmp_path_factory.mktemp("fair")
    with tarfile.open(ARCHIVE) as tar:
        tar.extractall(folder, **({"filter": "data"} if hasattr(tarfile, "data_filter") else {}))
    root = folder / "lr3e-4"
    assert sorted(runs.read_json(root / "sweep.json")["methods"]) == sorted(ARMS.values())
    loaded = compare.load(root)
    return {short: loaded[name] for short, name in ARMS.items()}


def signed(x: float) -> str:
    return f"{x:+.1f}".replace("+-", "-")


def test_results_md_quotes_the_sweep(study):
    results = (REPO / "docs" / "results.md").read_text()
    readme = (REPO / "README.md").read_text()
    for arm, per_seed in study.items():
        assert [r["seed"] for r in per_seed] == [0, 1, 2, 3, 4]
        sr, spl = compare.values(per_seed, "SR"), compare.values(per_seed, "SPL")
        s, iqm = stats.summary(sr), stats.stratified_bootstrap_ci(stats.iqm, sr)
        row = (f"| {arm} | " + " / ".join(f"{x:.1f}" for x in sr) + f" | {s['mean']:.1f} ± {s['std']:.1f} | "
               f"{spl.mean():.1f} ± {spl.std(ddof=1):.1f} | {iqm[0]:.1f} [{iqm[1]:.1f}, {iqm[2]:.1f}] |")
        assert row in results, row
    p_values = [stats.paired(compare.values(study[a], "SR"), compare.values(study[b], "SR"))["p"] for a, b in PAIRS]
    for (a, b), p_holm in zip(PAIRS, stats.holm(p_values)):
        x, y = compare.values(study[a], "SR"), compare.values(study[b], "SR")
        cells = []
        for column in ("SR", "SPL"):
            pair = stats.paired(compare.values(study[a], column), compare.values(study[b], column))
            cells.append(f"{signed(pair['diff'])} [{signed(pair['ci_low'])}, {signed(pair['ci_high'])}]")
        poi = stats.stratified_bootstrap_ci(stats.probability_of_improvement, y, x)
        mde = stats.minimum_detectable_effect(float(np.std(y - x, ddof=1)), len(x))
        row = (f"| {b} - {a} | {cells[0]} | {cells[1]} | {poi[0]:.2f} [{poi[1]:.2f}, {poi[2]:.2f}] | "
               f"{p_holm:.3f} | {mde:.1f} |")
        assert row in results, row
    headline = stats.paired(compare.values(study["a3c"], "SR"), compare.values(study["a3c+foresit"], "SR"))
    quoted = f"{signed(headline['diff'])} [{signed(headline['ci_low'])}, {signed(headline['ci_high'])}]"
    assert quoted in readme, quoted


def test_the_base_is_ahead_on_every_seed_as_results_md_says(study):
    gaps = compare.values(study["a3c"], "SR") - compare.values(study["a3c+foresit"], "SR")
    assert (gaps > 0).all()
    assert f"by {gaps.min():.1f} to {gaps.max():.1f} points" in (REPO / "docs" / "results.md").read_text()
