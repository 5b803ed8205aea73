"""The targets study's rules (docs/plans/imagination_targets.md) as code: the pilot's choice
of each target's weight, the first update at which validation SR reaches a level, and stage
1's comparisons (each target - the base, paired, Holm over the family). Pure functions of
results.json's per-seed records (`{arm: [seed's result, ...]}`); the words come from
`verdicts.verdict`."""

from __future__ import annotations

import math

import numpy as np

from experiments.reporting import report
from experiments.reporting.verdicts import Verdict, family_verdicts

# A tie in the pilot's rule (validation areas within this many points) keeps the larger weight.
TIE = 0.1


def target_of(arm: str) -> tuple[str, float]:
    """(aux_target, aux_weight) an arm sets ("none", 0.0 for an arm without a target), read from
    its `METHOD@field=value,...` (reporting reads no Config: the arm as the plan wrote it)."""
    _, _, body = arm.partition("@")
    fields = dict(item.strip().split("=", 1) for item in body.split(",") if "=" in item)
    return fields.get("aux_target", "none"), float(fields.get("aux_weight", 0.0))


def pilot_choice(results: dict[str, list[dict]]) -> dict[str, str]:
    """{target: the arm chosen}: per target, the arm whose mean validation SR area over the
    seeds is the larger; within `TIE` points, the larger weight."""
    by_target: dict[str, list[tuple[float, float, str]]] = {}
    for arm, per_seed in results.items():
        target, weight = target_of(arm)
        if target == "none":
            continue
        area = float(np.mean(report.values(per_seed, report.VALIDATION_AREA)))
        by_target.setdefault(target, []).append((area, weight, arm))
    chosen = {}
    for target, rows in by_target.items():
        best = max(area for area, _, _ in rows)
        near = [(weight, arm) for area, weight, arm in rows if area >= best - TIE]
        chosen[target] = max(near)[1]
    return chosen


def first_reaching(validation: list[dict], level: float = 50.0) -> float:
    """The first update at which one seed's validation SR (%) reaches `level`, linear between
    evaluations (from the first evaluation on; NaN if it never does)."""
    points = sorted((v["update"], report.rate(v["SR"])) for v in validation)
    for i, (update, sr) in enumerate(points):
        if sr >= level:
            if i == 0:
                return float(update)
            u0, s0 = points[i - 1]
            return float(u0 + (level - s0) / (sr - s0) * (update - u0))
    return math.nan


def stage1_verdicts(
    results: dict[str, list[dict]], base: str, family: list[str], metric: str = report.VALIDATION_AREA
) -> dict[str, Verdict]:
    """{arm: Verdict of arm - base on `metric`}, paired over the seeds, for the arms of
    `family` with Holm's correction over them (the primary measure's family)."""
    diffs = [report.values(results[arm], metric) - report.values(results[base], metric) for arm in family]
    return dict(zip(family, family_verdicts(diffs, metric, 3.8)))
