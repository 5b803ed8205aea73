"""The generated blocks of docs/priors.md, docs/houses.md and docs/foresight.md on made-up data
(the real archives' blocks are held by tests/experiments/test_regenerate.py): the pages read
the data folder of the `Archives` they are given, the levers' criterion names a family only
when a gain reaches it, and a setup's pairs are judged as one Holm family (`pages.common.family`,
which docs/priors.md's and docs/houses.md's pages judge with)."""

import json

import numpy as np

from experiments.reporting import registry
from experiments.reporting.pages import common, foresight_md


def measurement(gain: float, layout: str = "room", priors: bool = True, perception_range=None) -> dict:
    """One layout family as `experiments.foresight` writes it (turn and bearing alike)."""
    part = {
        "geometry": 0.7,
        "view": 0.7,
        "view + target": 0.7 + gain,
        "gain": gain,
        "gain_ci": [gain - 0.01, gain + 0.01],
    }
    subsets = {
        "anchor in view": {**part, "samples": 10, "share": 0.25},
        "anchor not in view": {**part, "samples": 30, "share": 0.75},
    }
    result = {**part, "test_samples": 40, "test_groups": 20, "majority": 0.5, "test_shares": [0.25, 0.25, 0.25, 0.25]}
    if priors:
        result["subsets"] = subsets
    args = {"setup": "savn", "layout": layout, "priors": priors, "resets": 20000, "perception_range": perception_range}
    return {"args": args, "results": {"turn": result, "bearing": result}}


def data_folder(tmp_path, largest: float):
    """docs/data's files, linked, with foresight_levers.json made up: its largest gain `largest`."""
    data = tmp_path / "data"
    data.mkdir(parents=True)
    for f in registry.DATA.iterdir():
        (data / f.name).symlink_to(f)
    levers = {
        k: measurement(0.01, priors="priors" in k, perception_range=6.0)
        for k in ("room-priors-range6", "house-priors-range6", "room-range6", "room-priors-range3", "room-range4")
    }
    levers["room-priors-range4"] = measurement(largest, perception_range=4.0)
    (data / "foresight_levers.json").unlink()
    (data / "foresight_levers.json").write_text(json.dumps(levers))
    return registry.Archives(data)


def test_the_tables_read_the_archives_data_folder(tmp_path):
    archives = data_folder(tmp_path, 0.031)
    rows = foresight_md.measured_table(archives, "range4").splitlines()
    assert (
        rows[2]
        == "| rooms with priors, range 4 | turn | 40 (20 layouts) | 50.0 | 70.0 | 70.0 | 73.1 | +3.1 [+2.1, +4.1] |"
    )
    assert (
        rows[3]
        == "| rooms with priors, range 4 | turn, anchor in view | 10 (25%) | | 70.0 | 70.0 | 73.1 | +3.1 [+2.1, +4.1] |"
    )


def test_a_family_is_named_only_when_a_gain_reaches_the_criterion(tmp_path):
    below = foresight_md.candidate(data_folder(tmp_path / "below", 0.049))
    assert below.startswith("No lever reaches 5 points") and "family kwargs" not in below
    reached = foresight_md.candidate(data_folder(tmp_path / "reached", 0.052))
    assert "family kwargs: priors=True perception_range=4\n" in reached
    assert "its point estimate reaches 5 points, its lower end (4.2) does not" in reached
    assert "with Eq. 7's noise, SR -4.1 [-6.1, -2.1]: costs" in reached  # the ceiling, from the real archives


def test_a_setups_three_pairs_are_one_holm_family():
    """B - A resolved alone (its 95% interval clear of 0) is "cannot tell" once Holm adjusts
    its p over the setup's three pairs (here "level": its 90% interval lies inside the margin)."""

    def arm(sr):
        return [{"seed": s, "selected": {"overall": {"SR": float(x)}}} for s, x in enumerate(sr)]

    base = np.array([50, 52, 54, 56, 58])
    results = {"a": arm(base), "b": arm(base + [1, 3, 0, 2, 2.5]), "c": arm(base + [1, -1, 0.5, -0.5, 0.2])}
    alone = common.alone(np.array([1, 3, 0, 2, 2.5]), "SR")
    judged = common.family(results, [("a", "b"), ("a", "c"), ("c", "b")], "SR")
    assert alone.word == "helps" and alone.figures() == judged[0].figures() == "+1.7 [+0.2, +3.2]"
    assert judged[0].word == "level" and judged[0].p > 0.05 > alone.p  # the 90% interval inside ±3.8
