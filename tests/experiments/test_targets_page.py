"""docs/targets.md's stage-1 blocks (`pages/targets_md.py`), written before stage 1 ran, on a
hand-made archive whose answers are known: the primary measure's Holm family, the arms
judged alone, the secondary measures, the first update at 50%, and the heads' probe."""

import json
import tarfile

import numpy as np
import pytest

from experiments.reporting import registry
from experiments.reporting.pages import targets_md

UPDATES = (500, 1000, 1500, 2000, 2500, 3000)


def seed(s, curve, sr, spl):
    validation = [{"update": u, "SR": v} for u, v in zip(UPDATES, curve)]
    return {"seed": s, "validation": validation, "selected": {"overall": {"SR": sr, "SPL": spl}}}


def area(curve):
    """The trapezoid over the evaluations, divided by their span (`report.VALIDATION_AREA`)."""
    return float(np.trapezoid(curve, UPDATES) / (UPDATES[-1] - UPDATES[0]))


# Flat curves at level c: the area is c. The base at 40 (+ each seed's offset; its seed 0
# rises through 50% between 1000 and 1500 updates, area 40 too). compass and goal_view gain
# with p about 0.030 and 0.027 alone, so each 95% interval is clear of 0 alone, but Holm's
# adjusted p is 0.054 for both; success spreads around 0; the rate and the input compass far off.
OFFSETS = [0.0, 1.0, -1.0, 2.0, -2.0]
BASE_SEED_0 = [20.0, 40.0, 60.0, 40.0, 30.0, 40.0]
GAINS = {
    "base": [0, 0, 0, 0, 0],
    "compass": [12, 1, 9, 4, 14],
    "goal_view": [3, 0.5, 4, 1, 2.5],
    "success": [3, -4, 5, -2, 1],
    "rate": [1, 2, 0, 1, 1],
    "input": [30, 31, 29, 30, 30],
}
ARMS = {
    "base": targets_md.BASE,
    "compass": targets_md.target_arm("compass"),
    "goal_view": targets_md.target_arm("goal_view"),
    "success": targets_md.target_arm("success"),
    "rate": "a3c@learning_rate=1e-3",
    "input": "a3c+compass+plaincritic@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0",
}


@pytest.fixture(scope="module")
def archives(tmp_path_factory):
    root = tmp_path_factory.mktemp("stage1")
    for key, arm in ARMS.items():
        results = []
        for i, (offset, gain) in enumerate(zip(OFFSETS, GAINS[key])):
            level = 40.0 + offset + gain
            curve = [level] * len(UPDATES)
            if key == "base" and i == 0:
                curve = BASE_SEED_0
            results.append(seed(i, curve, level, level / 2))
        folder = root / "targets_stage1" / "methods" / arm
        folder.mkdir(parents=True)
        (folder / "results.json").write_text(json.dumps({"results": results}))
    probe = {
        "episodes": 8,
        "seed": 0,
        "arms": {
            ARMS["compass"]: [
                {"seed": 0, "angular_error": 0.5, "learned": True},
                {"seed": 1, "angular_error": 0.7, "learned": False},
            ],
        },
    }
    (root / "targets_stage1" / "targets_probe.json").write_text(json.dumps(probe))
    (root / "data").mkdir()
    with tarfile.open(root / "data" / targets_md.STAGE1, "w:xz") as tar:
        tar.add(root / "targets_stage1", arcname="targets_stage1")
    return registry.Archives(root / "data")


def cells(text: str, label: str) -> list[str]:
    row = next(line for line in text.splitlines() if line.startswith(f"| {label}"))
    return [c.strip() for c in row.strip("|").split("|")]


def test_the_primary_measure_judges_the_family_with_holm_and_the_rest_alone(archives):
    from experiments.reporting.verdicts import verdict

    text = targets_md.stage1_primary(archives)
    assert area(BASE_SEED_0) == pytest.approx(40.0)
    assert cells(text, "the base")[2] == "40.0"
    compass, goal_view = cells(text, "`compass`"), cells(text, "`goal_view`")
    assert compass[3].startswith("+8.0 [") and goal_view[3].startswith("+2.2 [")
    assert compass[5] == goal_view[5] == "Holm over 2"
    # Alone, each gain's 95% interval is clear of 0: "helps"; in the family (Holm's p 0.054) not.
    for row, key in ((compass, "compass"), (goal_view, "goal_view")):
        assert verdict(GAINS[key], "area", 3.8).word == "helps"
        assert not row[4].startswith("helps"), row
    assert compass[4].startswith("cannot tell (MDE") and goal_view[4] == "level within ±3.8"
    assert cells(text, "`success`")[5] == "alone (exploratory)"
    assert cells(text, "`success`")[4].startswith("cannot tell")
    assert cells(text, "a3c at its validated rate")[5] == "alone"
    assert cells(text, "the compass as an input")[4] == "helps"


def test_the_secondary_measures_and_the_first_update_at_50(archives):
    text = targets_md.stage1_secondary(archives)
    # The base's seed 0: 40 at 1000, 60 at 1500, so 50% at 1250; the others stay at 38-42.
    assert cells(text, "the base")[-1] == "1250 (1 of 5 seeds)"
    # compass's levels: 52, 42, 48, 46, 52: seeds 0 and 4 are at 50% or more from the first evaluation.
    compass = cells(text, "`compass`")
    assert compass[-1] == "500 (2 of 5 seeds)"
    assert cells(text, "`success`")[-1] == "never"
    # The selected model's test SR is the level, its SPL half of it: SPL's difference is half SR's.
    assert compass[1].startswith("+8.0 [") and compass[3].startswith("+4.0 [")


def test_the_heads_probe_counts_the_seeds_that_learned(archives):
    text = targets_md.stage1_heads(archives)
    row = cells(text, "`compass`")
    assert row[1] == "1 of 2" and row[2] == "angular_error 0.6"
