"""docs/targets.md's generated blocks: the pilot's table; stage 1's (primary, secondary, the heads),
written before it ran and registered in `BLOCKS` once its archive existed; stage 2's first step
(the `compass` pair on fresh seeds), the same primary and secondary tables of its archive."""

from __future__ import annotations

import functools

import numpy as np

from experiments import rundir
from experiments.reporting import report, targets_study
from experiments.reporting.pages.ceiling_md import validation_table
from experiments.reporting.pages.common import alone, cells, differences, seed_by_seed, table
from experiments.reporting.registry import Archives, same_seeds


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


# ---------------------------------------------------------------------- stage 1
STAGE1 = "targets_stage1.tar.xz"
BASE = "a3c@learning_rate=3e-4"
TARGETS = ("compass", "goal_view", "success")
# Holm's family of the primary measure: `success` labelled 9.4% of valid steps in the pilot,
# under the plan's 10%, so it is exploratory (reported, judged alone).
FAMILY = ("compass", "goal_view")
REFERENCES = {
    "a3c at its validated rate (1e-3; a reference)": "a3c@learning_rate=1e-3",
    "the compass as an input, per step (privileged at test)": (
        "a3c+compass+plaincritic@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0"
    ),
}
PROBE_FILE = "targets_probe.json"


def target_arm(target: str, weight: str = "0.1") -> str:
    """Stage 1's arm of `target`, exactly as the plan's status writes it."""
    return f"{BASE},aux_target={target},aux_weight={weight}"


def _rows(results) -> list[tuple[str, str, str]]:
    """(label, arm, how it is judged) of every arm stage 1 compares with the base."""
    family = [t for t in FAMILY if target_arm(t) in results]
    holm = f"Holm over {len(family)}" if len(family) > 1 else "alone"
    rows = [(f"`{t}` as a target", target_arm(t), holm if t in family else "alone (exploratory)") for t in TARGETS]
    rows += [(label, arm, "alone") for label, arm in REFERENCES.items()]
    return [r for r in rows if r[1] in results]


def stage1_primary(archives: Archives, archive: str = STAGE1) -> str:
    """The plan's primary measure: each arm's area under the validation SR curve (500 updates
    to the run's last, in %) minus the base's, paired over the seeds; `compass` and `goal_view`
    one Holm family, the rest judged alone."""
    results = archives.sweep(archive)
    holm = targets_study.stage1_verdicts(results, BASE, [target_arm(t) for t in FAMILY if target_arm(t) in results])
    base = report.values(results[BASE], report.VALIDATION_AREA)
    rows = [[f"the base, `{BASE}`", seed_by_seed(base), f"{np.mean(base):.1f}", "", "", ""]]
    for label, arm, how in _rows(results):
        areas = report.values(results[arm], report.VALIDATION_AREA)
        v = holm.get(arm) or alone(differences(results, BASE, arm, report.VALIDATION_AREA), report.VALIDATION_AREA)
        rows.append([label, seed_by_seed(areas), f"{np.mean(areas):.1f}", *cells(v), how])
    header = ["arm", "validation SR area per seed", "mean", "minus the base [95% CI]", "verdict", "judged"]
    return table(header, rows)


def stage1_secondary(archives: Archives, archive: str = STAGE1) -> str:
    """The secondary measures: test SR and SPL of the selected model minus the base's (each
    judged alone), and the first update at which validation SR reaches 50% (linear between
    evaluations; the seeds that never reach it counted)."""
    results = archives.sweep(archive)
    rows = []
    for label, arm, _ in [(f"the base, `{BASE}`", BASE, "")] + _rows(results):
        firsts = np.array([targets_study.first_reaching(r["validation"]) for r in results[arm]])
        reached = firsts[np.isfinite(firsts)]
        first = f"{reached.mean():.0f} ({len(reached)} of {len(firsts)} seeds)" if len(reached) else "never"
        if arm == BASE:
            pairs = ["", "", "", ""]
        else:
            pairs = [c for m in ("SR", "SPL") for c in cells(alone(differences(results, BASE, arm, m), m))]
        rows.append([label, *pairs, first])
    header = ["arm", "test SR minus the base", "verdict", "test SPL minus the base", "verdict", "validation SR 50% at"]
    return table(header, rows)


def stage1_heads(archives: Archives, archive: str = STAGE1) -> str:
    """Did each head learn (`experiments.target_probe`'s file in the archive): per target, the
    seeds whose head beats a predictor of the mean label, and each measure's mean over the
    seeds (the compass's angular error beside the mean's, the R² of its distance; a latent's
    R², and the spread of its labels across episodes beside the states')."""
    name = next(n for n in archives.names(archive) if n.endswith("/" + PROBE_FILE))
    probe = archives.member(archive, name)
    rows = []
    for arm, seeds in probe["arms"].items():
        target, _ = targets_study.target_of(arm)
        measures = [k for k in seeds[0] if k not in ("seed", "learned")]
        means = ", ".join(f"{k} {np.nanmean([s[k] for s in seeds]):.3g}" for k in measures)
        label = f"`{target}`" + (" permuted" if arm.endswith("aux_permute=true") else "")
        rows.append([label, f"{sum(bool(s['learned']) for s in seeds)} of {len(seeds)}", means])
    return table(["target", "heads that beat the mean label", "means over the seeds"], rows)


# ---------------------------------------------------------------------- stage 2
# The plan's stage 2 for the one target whose primary interval excluded 0 after Holm in stage 1
# (`compass`): first the same pair on fresh seeds 5-9, same family and machine. One pair, judged
# alone; the tables are stage 1's, of this archive.
STAGE2 = "targets_stage2.tar.xz"


# The content control (the plan's status, declared before its results): `compass` against the
# same head trained on the labels of another lane (`aux_permute`), seeds 5-9, each pair judged
# alone; its base and `compass` arms retrained beside stage 2's, from a worktree at v0.4.0.
CONTENT = "targets_stage2_content.tar.xz"
PERMUTED = f"{target_arm('compass')},aux_permute=true"
CONTENT_PAIRS = (
    ("`compass` - `compass` permuted (the primary)", PERMUTED, target_arm("compass")),
    ("`compass` permuted - the base", BASE, PERMUTED),
    ("`compass` - the base (stage 2's pair, retrained)", BASE, target_arm("compass")),
)


def content_control(archives: Archives, archive: str = CONTENT) -> str:
    """The content control's arms (each seed's validation SR area) and its three pairs on the
    primary measure, test SR and test SPL, each judged alone; then, seed by seed, whether the
    retrained base and `compass` arms give stage 2's numbers."""
    results = archives.sweep(archive)
    labels = {
        BASE: f"the base, `{BASE}`",
        target_arm("compass"): "`compass` as a target",
        PERMUTED: "`compass` permuted",
    }
    arms = table(
        ["arm", "validation SR area per seed", "mean"],
        [
            [label, seed_by_seed(a := report.values(results[arm], report.VALIDATION_AREA)), f"{np.mean(a):.1f}"]
            for arm, label in labels.items()
        ],
    )
    rows = []
    for label, a, b in CONTENT_PAIRS:
        for metric in (report.VALIDATION_AREA, "SR", "SPL"):
            v = alone(differences(results, a, b, metric), metric)
            rows.append(
                [label, "validation SR area" if metric == report.VALIDATION_AREA else f"test {metric}", *cells(v)]
            )
    pairs = table(["B - A", "metric", "mean [95% CI]", "verdict"], rows)
    return arms + "\n" + pairs + "\n" + repeated_stage2(results, archives.sweep(STAGE2))


def repeated_stage2(results: dict[str, list[dict]], stage2: dict[str, list[dict]], what: str = "retrained") -> str:
    """One sentence per arm of stage 2: in how many seeds the arm's validation SR area, test
    SR and SPL in `results` (`what` they are) equal stage 2's exactly."""
    out = []
    for arm in (BASE, target_arm("compass")):
        measures = (report.VALIDATION_AREA, "SR", "SPL")
        same_seeds(results[arm], stage2[arm], f"{arm} {what} against stage 2's")
        same = [
            all(report.values([new], m)[0] == report.values([old], m)[0] for m in measures)
            for new, old in zip(results[arm], stage2[arm], strict=True)
        ]
        out.append(
            f"`{arm}` {what}: the validation SR area, test SR and SPL equal stage 2's in "
            f"{sum(same)} of {len(same)} seeds."
        )
    return "\n".join(out) + "\n"


# The pair in today's rooms (no priors, no perception range), seeds 5-9: stage 2's first step's
# tables, of this archive.
ROOMS = "targets_stage2_rooms.tar.xz"


# The pair extended to 9000 updates (the plan's status, its comparisons fixed before it ran):
# stage 2's pair continued from its own 3000-update checkpoints, seeds 5-9; the primary and
# secondary tables of this archive, then each arm's change from its own 3000-update models.
NINE = "targets_stage2_9000.tar.xz"
NINE_UPDATES = (3000, 4500, 6000, 7500, 9000)


def budget(archives: Archives, archive: str = NINE) -> str:
    """The pair extended to 9000 updates: each arm's mean validation SR at `NINE_UPDATES`;
    each arm's 9000-update models minus its own 3000-update ones (test SR and SPL, paired over
    the seeds, each judged alone); the pair's difference at both budgets; and whether the
    3000-update results the run kept are stage 2's archive's."""
    kept = rundir.kept_results(3000)
    arms = ((BASE, f"the base, `{BASE}`"), (target_arm("compass"), "`compass` as a target"))
    before = {arm: archives.results(archive, arm, kept) for arm, _ in arms}
    after = {arm: archives.results(archive, arm) for arm, _ in arms}

    curve = validation_table(archives, archive, arms, digits=1, updates=NINE_UPDATES)
    rows = []
    for arm, label in arms:
        same_seeds(before[arm], after[arm], f"{arm} at 3000 and at 9000 updates")
        row = [f"{label}: 9000 - 3000 updates"]
        for metric in ("SR", "SPL"):
            row += cells(alone(report.values(after[arm], metric) - report.values(before[arm], metric), metric))
        rows.append(row)
    for name, results in (("3000", before), ("9000", after)):
        row = [f"`compass` - the base, at {name} updates"]
        for metric in ("SR", "SPL"):
            row += cells(alone(differences(results, BASE, target_arm("compass"), metric), metric))
        rows.append(row)
    changes = table(["paired over seeds 5-9", "test SR [95% CI]", "verdict", "test SPL [95% CI]", "verdict"], rows)
    return curve + "\n" + changes + "\n" + repeated_stage2(before, archives.sweep(STAGE2), "at 3000 updates, kept")


def results_answer(archives: Archives) -> str:
    """docs/results.md's answer: the primary tables of stage 1, of stage 2's first step and of
    the pair at 9000 updates, and the content control's."""
    return (
        "Stage 1 (seeds 0-4):\n\n"
        + stage1_primary(archives)
        + "\nStage 2, the `compass` pair on fresh seeds 5-9:\n\n"
        + stage1_primary(archives, STAGE2)
        + "\nStage 2's content control (seeds 5-9; the same head trained on another lane's labels):\n\n"
        + content_control(archives)
        + "\nStage 2's pair extended to 9000 updates (seeds 5-9; the area over updates 500 to 9000):\n\n"
        + stage1_primary(archives, NINE)
    )


BLOCKS = {
    "results-targets": ("docs/results.md", results_answer),
    "targets-pilot": ("docs/targets.md", targets_pilot),
    "targets-stage1-primary": ("docs/targets.md", stage1_primary),
    "targets-stage1-secondary": ("docs/targets.md", stage1_secondary),
    "targets-stage1-heads": ("docs/targets.md", stage1_heads),
    "targets-stage2-primary": ("docs/targets.md", functools.partial(stage1_primary, archive=STAGE2)),
    "targets-stage2-secondary": ("docs/targets.md", functools.partial(stage1_secondary, archive=STAGE2)),
    "targets-content": ("docs/targets.md", content_control),
    "targets-rooms-primary": ("docs/targets.md", functools.partial(stage1_primary, archive=ROOMS)),
    "targets-rooms-secondary": ("docs/targets.md", functools.partial(stage1_secondary, archive=ROOMS)),
    "targets-content-heads": ("docs/targets.md", functools.partial(stage1_heads, archive=CONTENT)),
    "targets-9000-primary": ("docs/targets.md", functools.partial(stage1_primary, archive=NINE)),
    "targets-9000-secondary": ("docs/targets.md", functools.partial(stage1_secondary, archive=NINE)),
    "targets-9000-budget": ("docs/targets.md", budget),
}
