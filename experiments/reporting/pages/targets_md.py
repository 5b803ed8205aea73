"""docs/targets.md's generated blocks: the pilot's table (stage 1's and 2's join it once archived)."""

from __future__ import annotations

import numpy as np

from experiments.reporting import report, targets_study
from experiments.reporting.pages.common import seed_by_seed
from experiments.reporting.registry import Archives


def targets_pilot(archives: Archives, archive: str = "targets_pilot.tar.xz") -> str:
    """The targets pilot's table (docs/plans/imagination_targets.md): per arm, each seed's
    validation SR area, their mean, the share of valid steps its target labels (the mean over
    seeds of each chunk's mean), and the weight the plan's rule chooses per target
    (`targets_study.pilot_choice`)."""
    results = archives.sweep(archive)
    chosen = set(targets_study.pilot_choice(results).values())
    rows = []
    for arm, per_seed in sorted(results.items(), key=lambda kv: targets_study.target_of(kv[0])):
        target, weight = targets_study.target_of(arm)
        areas = report.values(per_seed, report.VALIDATION_AREA)
        labelled = [np.mean(r["diagnostics"]["charts/aux_labelled_fraction"]) for r in per_seed]
        rows.append(
            f"| {target} | {weight:g} | {seed_by_seed(areas)} | {np.mean(areas):.1f} | "
            f"{100 * np.mean(labelled):.1f}% | {'**chosen**' if arm in chosen else ''} |"
        )
    header = (
        "| target | weight | validation SR area per seed | mean | valid steps labelled | |\n|---|---|---|---|---|---|\n"
    )
    return header + "\n".join(rows) + "\n"


BLOCKS = {"targets-pilot": ("docs/targets.md", targets_pilot)}
