"""experiments.reporting.targets_study: the targets study's rules on hand-made results."""

import math

import numpy as np
import pytest

from experiments.reporting import targets_study as T


def seed(curve, sr=50.0):
    """One seed's results.json record with a validation curve [(update, SR %)]."""
    return {
        "seed": 0,
        "validation": [{"update": u, "SR": s} for u, s in curve],
        "selected": {"overall": {"SR": sr, "SPL": sr / 2, "SR>=5": None}},
    }


def test_the_pilot_chooses_each_targets_weight_by_validation_area():
    low = [seed([(500, 10.0), (1000, 30.0), (1500, 40.0)])]  # area (20 + 35) / 2 = 27.5
    high = [seed([(500, 10.0), (1000, 20.0), (1500, 40.0)])]  # area (15 + 30) / 2 = 22.5
    tie = [seed([(500, 10.0), (1000, 30.0), (1500, 40.2)])]  # 27.55: within TIE of 27.5
    results = {
        "a3c@aux_target=compass,aux_weight=0.1": low,
        "a3c@aux_target=compass,aux_weight=1.0": high,
        "a3c@aux_target=success,aux_weight=0.1": tie,
        "a3c@aux_target=success,aux_weight=1.0": low,
        "a3c": high,
    }
    assert T.pilot_choice(results) == {
        "compass": "a3c@aux_target=compass,aux_weight=0.1",
        "success": "a3c@aux_target=success,aux_weight=1.0",  # a tie keeps the larger weight
    }


def test_first_reaching_interpolates_between_evaluations():
    assert T.first_reaching([{"update": 500, "SR": 40.0}, {"update": 1000, "SR": 60.0}]) == 750.0
    assert T.first_reaching([{"update": 500, "SR": 55.0}]) == 500.0
    assert math.isnan(T.first_reaching([{"update": 500, "SR": 10.0}, {"update": 1000, "SR": 49.9}]))


def test_stage1_verdicts_pair_each_target_with_the_base_under_holm():
    rng = np.random.default_rng(0)
    base = [seed([(500, 20.0), (1000, 30.0)], sr=60.0 + x) for x in rng.normal(size=5)]
    better = [seed([(500, 30.0 + i), (1000, 45.0 + i)]) for i in range(5)]  # area +12.5 + i
    same = [seed([(500, 20.0 + (-1) ** i), (1000, 30.0)]) for i in range(5)]
    v = T.stage1_verdicts({"a3c": base, "x": better, "y": same}, "a3c", ["x", "y"])
    assert v["x"].word == "helps" and v["x"].diff == pytest.approx(12.5 + 2.0)
    assert v["y"].word in ("level", "cannot tell") and v["x"].p <= 1.0
