"""docs/ceiling.md's generated blocks: the ceiling study's and the channels study's
(docs/plans/ceiling_channels.md) tables, each pair judged by the project's one rule
(`verdicts.verdict`, the paper's margin `registry.PAPER_MARGIN`), and the plan's own rules
where the plan states them exactly (rule 1: a compass passes when its SR interval's lower end
is at least the pair's MDE of SR; rule 2: a ceiling is resolved when its SR interval lies
above 0 and its Holm-adjusted p over the family is below 0.05; rule 3: the best channel has
the highest mean validation SR of its selected models).

A family for Holm's correction is what the section's own `experiments.compare` command
declares (its `--pairs`; stage 2: the three goal-view ceilings, the plan's family of rule 2);
every other pair is judged alone.

Its formats and the Holm family's verdicts are `pages.common`'s; its pairs `registry.Pair`s.
"""

from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from experiments import rundir
from experiments.reporting import report, stats
from experiments.reporting.pages.common import (
    cells,
    figures,
    interval,
    judged,
    mean_std,
    probe_condition,
    seed_by_seed,
    table,
)
from experiments.reporting.registry import Archives, Pair, Ref
from experiments.reporting.verdicts import Verdict

PAGE = "docs/ceiling.md"

CRITIC = "a3c+critic@learning_rate=3e-4"
FORESIT = "a3c+foresit@learning_rate=3e-4"
ORACLE = "a3c+oracle@learning_rate=3e-4"
NOISEOFF = "a3c+oracle@learning_rate=3e-4,sigma2_max=0"  # also the goal view through `head`, no noise
COMPASS = "a3c+compass@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0"
START = "a3c+startcompass@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0"
ENC = "a3c+oracle@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0"
MLP_CRITIC = "a3c+critic@learning_rate=3e-4,imagination_input=mlp"
MLP = "a3c+oracle@learning_rate=3e-4,imagination_input=mlp,sigma2_max=0"
HEAD = NOISEOFF

ENTROPY = "losses/entropy"


# ---------------------------------------------------------------------- pairs and their verdicts
def pair(label: str, archive: str, a: str, b: str) -> Pair:
    """B - A of two arms of one archive."""
    return Pair(Ref(archive, a), Ref(archive, b), label)


def rule_1(v: Verdict) -> str:
    """The plan's rule 1 on an SR verdict: the interval's lower end at least the MDE."""
    return "passes" if v.ci95[0] >= v.mde else "does not pass"


def rule_2(v: Verdict) -> str:
    """The plan's rule 2 on an SR verdict judged in its family: above 0, Holm's p below 0.05."""
    return "resolved" if v.ci95[0] > 0 and v.p < 0.05 else "not resolved"


def p_header(pairs: Sequence[Pair], family: bool) -> str:
    return f"Holm p of SR ({len(pairs)} pairs)" if family and len(pairs) > 1 else "p of SR"


def pairs_table(archives: Archives, pairs: Sequence[Pair], family: bool = False, head: str = "pair") -> str:
    """| pair | SR [95% CI] | verdict, SR | SPL [95% CI] | verdict, SPL | p of SR |."""
    sr, spl = (judged(archives, pairs, m, family) for m in ("SR", "SPL"))
    rows = [[p.label, *cells(a), *cells(b), f"{a.p:.3f}"] for p, a, b in zip(pairs, sr, spl)]
    header = [head, "SR [95% CI]", "verdict, SR", "SPL [95% CI]", "verdict, SPL", p_header(pairs, family)]
    return table(header, rows)


def arm_row(per_seed: list[dict], label: str) -> list[str]:
    sr, spl = (report.values(per_seed, c) for c in ("SR", "SPL"))
    return [label, seed_by_seed(sr), mean_std(sr), mean_std(spl)]


def arms_table(archives: Archives, archive: str, arms: Sequence[tuple[str, str]]) -> str:
    """| arm | SR per seed | SR (mean ± std) | SPL (mean ± std) |."""
    rows = [arm_row(archives.results(archive, arm), label) for arm, label in arms]
    return table(["arm", "SR per seed", "SR (mean ± std)", "SPL (mean ± std)"], rows)


def share_line(archives: Archives, archive: str, foresit: str, oracle: str, name: str = "a3c+oracle") -> str:
    """The share of the ceiling (oracle - critic) a3c+foresit closes on SR, where the ceiling's
    interval excludes 0 (`stats.share_closed`, as `experiments.compare --ceiling`)."""
    base = report.values(archives.results(archive, CRITIC), "SR")
    gap, top = (report.values(archives.results(archive, arm), "SR") - base for arm in (foresit, oracle))
    share = stats.share_closed(gap, top)
    name = f"The share a3c+foresit closes, (a3c+foresit - a3c+critic) / ({name} - a3c+critic), on SR"
    if not share["resolved"]:
        return f'{name}: not defined (the ceiling\'s 95% interval holds 0: "ceiling not resolved").\n'
    return (
        f"{name}: {share['share']:.2f} [{share['share_low']:.2f}, {share['share_high']:.2f}] "
        "(exact paired bootstrap over the seeds, 95%).\n"
    )


def diagnostics_table(archives: Archives, pairs: Sequence[Pair]) -> str:
    """Each pair's training SR (the last 250 updates) and the policy's entropy (the last
    chunk's mean), paired over seeds: intervals only (the margin is in test SR points)."""
    rows = []
    for p in pairs:
        row = [p.label]
        for column, digits in ((report.TRAINING, 1), (ENTROPY, 2)):
            d = stats.summary(p.differences(archives, column))
            row.append(interval(d["mean"], d["ci_low"], d["ci_high"], digits))
        rows.append(row)
    return table(["pair", "training SR, last 250 updates [95% CI]", "policy entropy, last chunk [95% CI]"], rows)


def joined(*parts: str) -> str:
    return "\n".join(parts)


# ---------------------------------------------------------------------- the ceiling study
SAVN, PRIORS = "ceiling_savn.tar.xz", "ceiling_priors.tar.xz"
SAVN_NOISEOFF, SAVN_EPYC = "ceiling_savn_noiseoff.tar.xz", "ceiling_savn_epyc.tar.xz"
PRIORS_EPYC, PRIORS_NOISEOFF = "ceiling_priors_epyc.tar.xz", "ceiling_priors_noiseoff.tar.xz"
RANGE4, RANGE4_NOISEOFF = "ceiling_range4.tar.xz", "ceiling_range4_noiseoff.tar.xz"
THREE = ((CRITIC, "a3c+critic"), (FORESIT, "a3c+foresit"), (ORACLE, "a3c+oracle (privileged)"))
CEILING = "the ceiling: a3c+oracle (privileged) - a3c+critic"
NOISEOFF_CEILING = "the noise-off ceiling: a3c+oracle@sigma2_max=0 - a3c+critic"


@dataclasses.dataclass(frozen=True)
class Family:
    """A section's pairs, and whether its command declares them one family (Holm's correction)."""

    pairs: tuple[Pair, ...]
    declared: bool = False

    def judged(self, archives: Archives, metric: str) -> list[Verdict]:
        return judged(archives, self.pairs, metric, holm=self.declared)

    def table(self, archives: Archives, head: str = "pair") -> str:
        return pairs_table(archives, self.pairs, self.declared, head)


def _seed_matched(archive: str) -> Family:  # the command's --pairs: the ceiling alone
    return Family((pair(CEILING, archive, CRITIC, ORACLE), pair("a3c+foresit - a3c+critic", archive, CRITIC, FORESIT)))


SAVN_PAIRS = _seed_matched(SAVN)
PRIORS_PAIRS = _seed_matched(PRIORS)
SAVN_NOISEOFF_PAIRS = Family(
    (
        pair(NOISEOFF_CEILING, SAVN_NOISEOFF, CRITIC, NOISEOFF),
        pair("a3c+oracle@sigma2_max=0 - a3c+oracle (both privileged)", SAVN_NOISEOFF, ORACLE, NOISEOFF),
    ),
    declared=True,
)
SAVN_EPYC_PAIRS = Family(
    (pair(CEILING, SAVN_EPYC, CRITIC, ORACLE), pair(NOISEOFF_CEILING, SAVN_EPYC, CRITIC, NOISEOFF)), declared=True
)
PRIORS_EPYC_PAIRS = Family(
    (pair("the ceiling in rooms with priors: a3c+oracle (privileged) - a3c+critic", PRIORS_EPYC, CRITIC, ORACLE),)
)
PRIORS_NOISEOFF_PAIRS = Family(
    (
        pair(
            "the noise-off ceiling in rooms with priors: a3c+oracle@sigma2_max=0 - a3c+critic",
            PRIORS_NOISEOFF,
            CRITIC,
            NOISEOFF,
        ),
    )
)
RANGE4_PAIRS = Family((pair("the ceiling at range 4: a3c+oracle (privileged) - a3c+critic", RANGE4, CRITIC, ORACLE),))
RANGE4_NOISEOFF_PAIRS = Family(
    (
        pair(
            "the noise-off ceiling at range 4: a3c+oracle@sigma2_max=0 - a3c+critic", RANGE4_NOISEOFF, CRITIC, NOISEOFF
        ),
        pair("a3c+oracle@sigma2_max=0 - a3c+oracle at range 4 (both privileged)", RANGE4_NOISEOFF, ORACLE, NOISEOFF),
    ),
    declared=True,
)
SAME = "pair, same machine and seeds"


def ceiling_savn(archives: Archives) -> str:
    return joined(
        arms_table(archives, SAVN, THREE), SAVN_PAIRS.table(archives), share_line(archives, SAVN, FORESIT, ORACLE)
    )


def ceiling_priors(archives: Archives) -> str:
    holm = judged(archives, PRIORS_PAIRS.pairs, "SR")[0].p
    return joined(
        arms_table(archives, PRIORS, THREE),
        PRIORS_PAIRS.table(archives),
        share_line(archives, PRIORS, FORESIT, ORACLE),
        "The table judges each pair alone (the command's `--pairs` names the ceiling alone); Holm's p of "
        f"the ceiling's SR over the table's two pairs: {holm:.3f}.\n",
    )


def _probe_table(methods: dict, arms: Sequence[tuple[str, str, Sequence[str]]], with_arm: bool) -> str:
    labels = {
        "noise off": "noise off",
        "shuffled": "shuffled (another episode's goal view)",
        "shuffled, noise off": "shuffled, noise off",
    }
    rows = []
    for arm, name, conditions in arms:
        seeds = methods[arm]
        trained = [r["sr"]["trained"] for r in seeds]
        rows.append(([name] if with_arm else []) + ["trained", mean_std(trained), "", ""])
        for condition in conditions:
            sr = [r["sr"][condition] for r in seeds]
            v = probe_condition(seeds, condition)
            rows.append(([name] if with_arm else []) + [labels[condition], mean_std(sr), *cells(v)])
    header = ["condition", "SR (mean ± std)", "minus trained [95% CI]", "verdict"]
    return table((["arm"] if with_arm else []) + header, rows)


def ceiling_probe_savn(archives: Archives) -> str:
    methods = archives.probe("ceiling_probe_savn.json")
    return _probe_table(methods, [(ORACLE, "", ("noise off", "shuffled", "shuffled, noise off"))], with_arm=False)


def ceiling_savn_noiseoff(archives: Archives) -> str:
    return joined(
        arms_table(archives, SAVN_NOISEOFF, [(NOISEOFF, "a3c+oracle@sigma2_max=0 (privileged)")]),
        SAVN_NOISEOFF_PAIRS.table(archives),
        share_line(archives, SAVN_NOISEOFF, FORESIT, NOISEOFF, "a3c+oracle@sigma2_max=0"),
        diagnostics_table(archives, SAVN_NOISEOFF_PAIRS.pairs[1:]),
    )


def _machine_shift(archives: Archives, epyc: str, xeon: str, label: str) -> str:
    shift = Pair(Ref(xeon, CRITIC), Ref(epyc, CRITIC), label)
    return pairs_table(archives, [shift], head="the same program and seeds on two machines")


def ceiling_savn_epyc(archives: Archives) -> str:
    return joined(
        arms_table(archives, SAVN_EPYC, [(CRITIC, "a3c+critic, on the EPYC")]),
        SAVN_EPYC_PAIRS.table(archives, SAME),
        _machine_shift(archives, SAVN_EPYC, SAVN, "a3c+critic: EPYC - Xeon"),
    )


def ceiling_priors_epyc(archives: Archives) -> str:
    return joined(
        arms_table(archives, PRIORS_EPYC, [(CRITIC, "a3c+critic, on the EPYC, rooms with priors")]),
        PRIORS_EPYC_PAIRS.table(archives, SAME),
        _machine_shift(archives, PRIORS_EPYC, PRIORS, "a3c+critic in rooms with priors: EPYC - Xeon"),
    )


def ceiling_priors_noiseoff(archives: Archives) -> str:
    label = "a3c+oracle@sigma2_max=0 (privileged), on the EPYC, rooms with priors"
    return joined(
        arms_table(archives, PRIORS_NOISEOFF, [(NOISEOFF, label)]), PRIORS_NOISEOFF_PAIRS.table(archives, SAME)
    )


def ceiling_range4(archives: Archives) -> str:
    arms = [
        (CRITIC, "a3c+critic, on the EPYC, rooms with priors, range 4"),
        (ORACLE, "a3c+oracle (privileged), on the EPYC, rooms with priors, range 4"),
    ]
    return joined(
        arms_table(archives, RANGE4, arms),
        RANGE4_PAIRS.table(archives, SAME),
        diagnostics_table(archives, RANGE4_PAIRS.pairs),
    )


def ceiling_range4_noiseoff(archives: Archives) -> str:
    label = "a3c+oracle@sigma2_max=0 (privileged), on the EPYC, rooms with priors, range 4"
    return joined(
        arms_table(archives, RANGE4_NOISEOFF, [(NOISEOFF, label)]), RANGE4_NOISEOFF_PAIRS.table(archives, SAME)
    )


def curves(per_seed: list[dict]) -> dict[int, np.ndarray]:
    """{update: each seed's validation SR there} (results.json's validation evaluations)."""
    out: dict[int, list[float]] = {}
    for r in per_seed:
        for v in r["validation"]:
            out.setdefault(v["update"], []).append(v["SR"])
    if any(len(x) != len(per_seed) for x in out.values()):
        raise ValueError("a validation evaluation is missing from some seed")
    return {u: np.array(x, float) for u, x in sorted(out.items())}


def ceiling_range4_along_training(archives: Archives) -> str:
    critic = curves(archives.results(RANGE4_NOISEOFF, CRITIC))
    oracles = {arm: curves(archives.results(RANGE4_NOISEOFF, arm)) for arm in (ORACLE, NOISEOFF)}
    rows, above, below = [], dict.fromkeys(oracles, 0), dict.fromkeys(oracles, 0)
    for update, base in critic.items():
        row = [str(update), mean_std(base)]
        for arm, curve in oracles.items():
            d = stats.paired(base, curve[update])
            row.append(figures(d))
            above[arm] += d["ci_low"] > 0
            below[arm] += d["ci_high"] < 0
        rows.append(row)
    header = [
        "update",
        "a3c+critic, validation SR",
        "a3c+oracle - a3c+critic",
        "a3c+oracle@sigma2_max=0 - a3c+critic",
    ]
    n = len(critic)
    counts = "; ".join(
        f"{name}: {above[arm]} of {n} wholly above 0, {below[arm]} of {n} wholly below 0"
        for arm, name in ((ORACLE, "a3c+oracle"), (NOISEOFF, "a3c+oracle@sigma2_max=0"))
    )
    return table(header, rows) + f"\nThe intervals (95%, each uncorrected for the others), {counts}.\n"


def ceiling_probe_range4(archives: Archives) -> str:
    methods = archives.probe("ceiling_probe_range4.json")
    arms = [
        (ORACLE, "a3c+oracle (Eq. 7's noise)", ("noise off", "shuffled", "shuffled, noise off")),
        (NOISEOFF, "a3c+oracle@sigma2_max=0", ("shuffled",)),
    ]
    return _probe_table(methods, arms, with_arm=True)


# ---------------------------------------------------------------------- the channels study
STAGE1, STAGE2, STAGE3, ROOMS = (
    "channels_stage1.tar.xz",
    "channels_stage2.tar.xz",
    "channels_stage3.tar.xz",
    "channels_rooms.tar.xz",
)


def validation_table(
    archives: Archives, archive: str, arms: Sequence[tuple[str, str]], digits: int, updates=None
) -> str:
    """Mean validation SR over seeds at each evaluated update (or at `updates`)."""
    means = {arm: {u: x.mean() for u, x in curves(archives.results(archive, arm)).items()} for arm, _ in arms}
    shown = updates or sorted(next(iter(means.values())))
    rows = [[name, *(f"{means[arm][u]:.{digits}f}" for u in shown)] for arm, name in arms]
    return table(["update", *map(str, shown)], rows)


def stage_1_pairs() -> list[Pair]:
    return [
        pair("the compass per step - a3c+critic", STAGE1, CRITIC, COMPASS),
        pair("the compass at step 0 - a3c+critic", STAGE1, CRITIC, START),
    ]


def channels_stage1(archives: Archives) -> str:
    arms = arms_table(
        archives,
        STAGE1,
        [
            (CRITIC, "a3c+critic, rooms with priors, range 4 (channels study)"),
            (COMPASS, "a3c+compass through `encoder` (privileged), per step"),
            (START, "a3c+startcompass through `encoder` (privileged), held from the start"),
        ],
    )
    pairs = stage_1_pairs()
    sr, spl = (judged(archives, pairs, m) for m in ("SR", "SPL"))
    rows = [
        [p.label, *cells(a), *cells(b), f"{a.mde:.1f}", f"{a.p:.3f}", f"{b.p:.3f}", rule_1(a)]
        for p, a, b in zip(pairs, sr, spl)
    ]
    header = [
        "pair, same machine and seeds",
        "SR [95% CI]",
        "verdict, SR",
        "SPL [95% CI]",
        "verdict, SPL",
        "MDE of SR",
        "Holm p of SR (2 pairs)",
        "Holm p of SPL (2 pairs)",
        "the plan's rule 1",
    ]
    between = pairs_table(
        archives,
        [pair("the compass per step - the compass at step 0", STAGE1, START, COMPASS)],
        head="between the compasses",
    )
    return joined(arms, table(header, rows), between)


def channels_stage1_validation(archives: Archives) -> str:
    arms = ((CRITIC, "a3c+critic"), (COMPASS, "a3c+compass, per step"), (START, "a3c+startcompass"))
    return validation_table(archives, STAGE1, arms, digits=2)


STAGE2_ARMS = (
    (CRITIC, "a3c+critic (the base of `head` and `encoder`; stage 1's, copied)"),
    (MLP_CRITIC, "a3c+critic through `mlp` (the base of `mlp`)"),
    (ENC, "a3c+oracle through `encoder` (privileged), no noise"),
    (MLP, "a3c+oracle through `mlp` (privileged), no noise"),
    (HEAD, "a3c+oracle through `head` (privileged), no noise"),
)


# The family of the plan's rule 2: each goal-view arm over its own base.
STAGE2_CEILINGS = Family(
    (
        pair("the goal view through `encoder` - its base", STAGE2, CRITIC, ENC),
        pair("the goal view through `mlp` - its base", STAGE2, MLP_CRITIC, MLP),
        pair("the goal view through `head` - its base", STAGE2, CRITIC, HEAD),
    ),
    declared=True,
)
STAGE3_CEILING = Family((pair("the goal view through `head` - its base, 9000 updates", STAGE3, CRITIC, HEAD),))
ROOMS_CEILING = Family((pair("the goal view through `head` - its base, today's rooms", ROOMS, CRITIC, HEAD),))


def ceilings_table(archives: Archives, family: Family, area: bool) -> str:
    """A stage's goal-view ceilings, one family (Holm), with the plan's rule 2."""
    pairs = family.pairs
    metrics = ("SR", "SPL", report.VALIDATION_AREA) if area else ("SR", "SPL")
    judged_by = {m: family.judged(archives, m) for m in metrics}
    rows = []
    for i, p in enumerate(pairs):
        sr = judged_by["SR"][i]
        rows.append([p.label, *(c for m in metrics for c in cells(judged_by[m][i])), f"{sr.p:.3f}", rule_2(sr)])
    names = {"SR": "SR", "SPL": "SPL", report.VALIDATION_AREA: "validation SR area"}
    header = ["ceiling, same machine and seeds"]
    for m in metrics:
        header += [f"{names[m]} [95% CI]", f"verdict, {names[m]}"]
    n = len(pairs)
    header += [f"Holm p of SR ({n} pair{'s' if n > 1 else ''})", "the plan's rule 2"]
    return table(header, rows)


def channels_stage2(archives: Archives) -> str:
    differences = [
        pair("`encoder` - `head`", STAGE2, HEAD, ENC),
        pair("`mlp` - `head`", STAGE2, HEAD, MLP),
        pair("the critic: `mlp` - `head`", STAGE2, CRITIC, MLP_CRITIC),
    ]
    against_start = [
        Pair(Ref(STAGE1, START), Ref(STAGE2, arm), f"the goal view through {name} - the start compass (stage 1)")
        for arm, name in ((ENC, "`encoder`"), (MLP, "`mlp`"), (HEAD, "`head`"))
    ]
    resolved = sum(rule_2(v) == "resolved" for v in STAGE2_CEILINGS.judged(archives, "SR"))
    branch = (
        "the budget branch (3x quick's budget for the critic and the best channel)"
        if resolved == 0
        else "the content-control branch (the resolved channel's goal views shuffled, then ForeSIT through it)"
    )
    n = len(STAGE2_CEILINGS.pairs)
    return joined(
        arms_table(archives, STAGE2, STAGE2_ARMS),
        ceilings_table(archives, STAGE2_CEILINGS, area=False),
        f"The plan's rule 2 resolves {resolved} of the {n} ceilings, so its stage 3 takes {branch}.\n",
        pairs_table(archives, differences, head="channel difference (uncorrected)"),
        pairs_table(
            archives, against_start, head="against the timing-matched control, paired over seeds 0-4 (uncorrected)"
        ),
    )


def best_channel(archives: Archives) -> dict[str, float]:
    """The plan's rule 3: each goal-view arm's mean validation SR of its selected models."""

    def selected(r: dict) -> float:
        return next(v["SR"] for v in r["validation"] if v["update"] == r["selected_update"])

    return {arm: float(np.mean([selected(r) for r in archives.results(STAGE2, arm)])) for arm in (ENC, MLP, HEAD)}


def channels_stage2_validation(archives: Archives) -> str:
    arms = [(arm, label.split(" (")[0]) for arm, label in STAGE2_ARMS]
    chosen = best_channel(archives)
    names = {ENC: "`encoder`", MLP: "`mlp`", HEAD: "`head`"}
    ranked = sorted(chosen, key=chosen.get, reverse=True)
    rows = [[names[arm], f"{chosen[arm]:.2f}", "**best**" if arm == ranked[0] else ""] for arm in ranked]
    rule = table(["channel", "mean validation SR of the selected models", "the plan's rule 3"], rows)
    first, second = ranked[:2]
    lead = f"{names[first]} leads {names[second]} by {chosen[first] - chosen[second]:.1f} points.\n"
    return joined(validation_table(archives, STAGE2, arms, digits=2), rule, lead)


def channels_stage3(archives: Archives) -> str:
    arms = (
        (CRITIC, "a3c+critic, 9000 updates"),
        (HEAD, "a3c+oracle through `head` (privileged), no noise, 9000 updates"),
    )
    rows = []
    for arm, label in arms:
        change = Pair(Ref(STAGE3, arm, rundir.kept_results(3000)), Ref(STAGE3, arm))
        row = [f"{label.split(',')[0]}: 9000 - 3000 updates"]
        for metric in ("SR", "SPL"):
            row += cells(judged(archives, [change], metric)[0])
        rows.append(row)
    budget = table(
        [
            "the budget, seed by seed against the arm's own 3000-update models",
            "SR [95% CI]",
            "verdict, SR",
            "SPL [95% CI]",
            "verdict, SPL",
        ],
        rows,
    )
    return joined(arms_table(archives, STAGE3, arms), ceilings_table(archives, STAGE3_CEILING, area=True), budget)


def channels_stage3_validation(archives: Archives) -> str:
    arms = ((CRITIC, "a3c+critic"), (HEAD, "a3c+oracle through `head`"))
    return validation_table(archives, STAGE3, arms, digits=1, updates=(3000, 4500, 6000, 7500, 9000))


def channels_stage4(archives: Archives) -> str:
    arms = (
        (CRITIC, "a3c+critic, today's rooms (channels study)"),
        (HEAD, "a3c+oracle through `head` (privileged), no noise, today's rooms"),
    )
    this = ceilings_table(archives, ROOMS_CEILING, area=True)
    earlier = [
        pair("the same pair, the earlier run (2498418, docs/data/ceiling_savn_epyc.tar.xz)", SAVN_EPYC, CRITIC, HEAD)
    ]
    metrics = ("SR", "SPL", report.VALIDATION_AREA)
    verdicts = [judged(archives, earlier, m)[0] for m in metrics]
    old = table(
        [
            "the same pair, another run",
            "SR [95% CI]",
            "verdict, SR",
            "SPL [95% CI]",
            "verdict, SPL",
            "validation SR area [95% CI]",
            "verdict, validation SR area",
        ],
        [[earlier[0].label, *(c for v in verdicts for c in cells(v))]],
    )
    return joined(arms_table(archives, ROOMS, arms), this, old)


def channels_stage4_validation(archives: Archives) -> str:
    arms = ((CRITIC, "a3c+critic"), (HEAD, "a3c+oracle through `head`"))
    return validation_table(archives, ROOMS, arms, digits=1)


# ---------------------------------------------------------------------- every ceiling at once
def _anchor(name: str) -> str:
    return f"[{name}](#{SECTIONS[name]})"


SECTIONS = {
    "today's rooms": "the-ceiling-in-todays-rooms-savn-quick-seeds-0-4-2026-11-28",
    "without the noise": "without-the-noise-the-oracle-at-sigma2_max--0-savn-quick-seeds-0-4-2026-11-28",
    "machine-matched": "machine-matched-the-critic-retrained-on-the-epyc-savn-quick-seeds-0-4-2026-11-28",
    "rooms with priors": "the-ceiling-in-rooms-with-priors-savn-quick-seeds-0-4-2026-11-28",
    "priors, machine-matched": "machine-matched-in-rooms-with-priors-savn-quick-seeds-0-4-2026-11-28",
    "priors, without the noise": "machine-matched-in-rooms-with-priors-without-the-noise-savn-quick-seeds-0-4-2026-11-28",
    "range 4": "rooms-with-priors-range-4-savn-quick-seeds-0-4-2026-11-28",
    "range 4, without the noise": "rooms-with-priors-range-4-without-the-noise-savn-quick-seeds-0-4-2026-11-28",
    "stage 2": "stage-2-the-goal-view-through-three-channels-rooms-with-priors-range-4-quick-seeds-0-4-2026-11-29",
    "stage 3": "stage-3-three-times-the-budget-rooms-with-priors-range-4-seeds-0-4-2026-11-29",
    "stage 4": "stage-4-the-best-channel-in-todays-rooms-quick-seeds-0-4-2026-11-29",
}
# The rows' words: the rooms, i_tau's noise, how the pair's machines were matched.
IN_TODAY, IN_PRIORS, IN_RANGE4 = "today's rooms", "rooms with priors", "priors, range 4"
EQ7 = "Eq. 7's"
SEEDS_XEON = "seed-matched (the critic on the Xeon)"
AT_2498418, AT_79DCE9C, AT_431BBF4 = (f"machine-matched ({c})" for c in ("2498418", "79dce9c", "431bbf4"))
# (family, channel, i_tau's noise, updates, machines, the section's pairs, which of them, the section)
CEILINGS = (
    (IN_TODAY, "`head`", EQ7, 3000, SEEDS_XEON, SAVN_PAIRS, 0, "today's rooms"),
    (IN_TODAY, "`head`", "none", 3000, SEEDS_XEON, SAVN_NOISEOFF_PAIRS, 0, "without the noise"),
    (IN_TODAY, "`head`", EQ7, 3000, AT_2498418, SAVN_EPYC_PAIRS, 0, "machine-matched"),
    (IN_TODAY, "`head`", "none", 3000, AT_2498418, SAVN_EPYC_PAIRS, 1, "machine-matched"),
    (IN_TODAY, "`head`", "none", 3000, AT_431BBF4, ROOMS_CEILING, 0, "stage 4"),
    (IN_PRIORS, "`head`", EQ7, 3000, SEEDS_XEON, PRIORS_PAIRS, 0, "rooms with priors"),
    (IN_PRIORS, "`head`", EQ7, 3000, AT_2498418, PRIORS_EPYC_PAIRS, 0, "priors, machine-matched"),
    (IN_PRIORS, "`head`", "none", 3000, AT_2498418, PRIORS_NOISEOFF_PAIRS, 0, "priors, without the noise"),
    (IN_RANGE4, "`head`", EQ7, 3000, AT_79DCE9C, RANGE4_PAIRS, 0, "range 4"),
    (IN_RANGE4, "`head`", "none", 3000, AT_79DCE9C, RANGE4_NOISEOFF_PAIRS, 0, "range 4, without the noise"),
    (IN_RANGE4, "`encoder`", "none", 3000, AT_431BBF4, STAGE2_CEILINGS, 0, "stage 2"),
    (IN_RANGE4, "`mlp`", "none", 3000, AT_431BBF4, STAGE2_CEILINGS, 1, "stage 2"),
    (IN_RANGE4, "`head`", "none", 3000, AT_431BBF4, STAGE2_CEILINGS, 2, "stage 2"),
    (IN_RANGE4, "`head`", "none", 9000, AT_431BBF4, STAGE3_CEILING, 0, "stage 3"),
)


def ceiling_summary(archives: Archives) -> str:
    """Every goal-view ceiling of the page (the oracle over its base), each judged as its
    section judges it (in its section's family)."""
    rows = []
    for family, channel, noise, updates, machines, pairs, i, section in CEILINGS:
        sr, spl = (pairs.judged(archives, m)[i] for m in ("SR", "SPL"))
        rows.append([family, channel, noise, f"{updates:,}", machines, *cells(sr), *cells(spl), _anchor(section)])
    header = [
        "rooms",
        "channel",
        "i_tau's noise",
        "updates",
        "machines",
        "SR [95% CI]",
        "verdict, SR",
        "SPL [95% CI]",
        "verdict, SPL",
        "section",
    ]
    return table(header, rows)


BLOCKS = {
    "ceiling-savn": (PAGE, ceiling_savn),
    "ceiling-probe-savn": (PAGE, ceiling_probe_savn),
    "ceiling-priors": (PAGE, ceiling_priors),
    "ceiling-savn-noiseoff": (PAGE, ceiling_savn_noiseoff),
    "ceiling-savn-epyc": (PAGE, ceiling_savn_epyc),
    "ceiling-priors-epyc": (PAGE, ceiling_priors_epyc),
    "ceiling-priors-noiseoff": (PAGE, ceiling_priors_noiseoff),
    "ceiling-range4": (PAGE, ceiling_range4),
    "ceiling-range4-noiseoff": (PAGE, ceiling_range4_noiseoff),
    "ceiling-range4-along-training": (PAGE, ceiling_range4_along_training),
    "ceiling-probe-range4": (PAGE, ceiling_probe_range4),
    "ceiling-summary": (PAGE, ceiling_summary),
    "channels-stage1": (PAGE, channels_stage1),
    "channels-stage1-validation": (PAGE, channels_stage1_validation),
    "channels-stage2": (PAGE, channels_stage2),
    "channels-stage2-validation": (PAGE, channels_stage2_validation),
    "channels-stage3": (PAGE, channels_stage3),
    "channels-stage3-validation": (PAGE, channels_stage3_validation),
    "channels-stage4": (PAGE, channels_stage4),
    "channels-stage4-validation": (PAGE, channels_stage4_validation),
}
