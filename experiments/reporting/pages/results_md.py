"""The generated blocks of docs/results.md and of the pages of its studies: the tables and
verdicts of the `fair` (docs/fair.md), `replication_3x` (docs/replication.md) and
`reference_ppo` (docs/reference_ppo.md) studies (registry.STUDIES); the figures of results.md's
"Does ForeSIT beat its base?" that come from an archive (the priors and houses rows among
them); and the ceiling and channels studies' pairs that results.md's "The paper's question with
power" quotes (docs/ceiling.md is their page).

Every pair is B - A paired over the seeds of its arms (`Pair`), judged by the project's one
rule (`verdicts.verdict`), with Holm's correction over a family (a tuple of `Pair`s) where the
section's table declares one ("p (Holm, 3 pairs)"). Arms are read from the archives in place
(`registry.Archives`: an extended run's results_3000_updates.json and the probes' and the PPO
reference's JSON files too); the formats and the Holm family's verdicts are `pages.common`'s.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np

from experiments import rundir
from experiments.reporting import report, stats, tuning
from experiments.reporting.pages.common import (
    bootstrap,
    judged,
    mean_std,
    paired_figures,
    probe_condition,
    seed_by_seed,
    signed,
    span,
    table,
)
from experiments.reporting.registry import (
    PAPER_MARGIN,
    VALIDATION,
    Archives,
    Chosen,
    Pair,
    Ref,
    Unchosen,
    same_seeds,
    values,
)
from experiments.reporting.verdicts import Verdict, verdict

RESULTS = "docs/results.md"
FAIR_PAGE, REPLICATION_PAGE, PPO_PAGE = "docs/fair.md", "docs/replication.md", "docs/reference_ppo.md"
AT_3000 = rundir.kept_results(3000)  # an extended run's results at its first budget

A3, A10 = "a3c@learning_rate=3e-4", "a3c@learning_rate=1e-3"
C3, C10 = "a3c+critic@learning_rate=3e-4", "a3c+critic@learning_rate=1e-3"
F3, F10 = "a3c+foresit@learning_rate=3e-4", "a3c+foresit@learning_rate=1e-3"
FW = "a3c+foresit@imagination_lr=3e-4"
NOISE = "a3c+foresit@learning_rate=3e-4,imagination_noise=input"
ORG = "a3c+org", "a3c+org+critic", "a3c+org+foresit"
RATES = ("3e-4", "1e-3")
SR_SPL = ("SR", "SPL")

TUNE, TUNE_3X, TUNE_ORG = "fair_tune.tar.xz", "fair_tune_3x.tar.xz", "fair_tune_org.tar.xz"
FIRST, THREE_X, BASES = "fair_lr3e-4.tar.xz", "fair_3x.tar.xz", "fair_bases.tar.xz"
FW_ARCHIVE, NOISE_ARCHIVE, REPLICATION = "fair_fw.tar.xz", "fair_noise.tar.xz", "replication_3x.tar.xz"
PROBE, PROBE_NOISE = "fair_probe_lr3e-4.json", "fair_probe_noise.json"
PPO_GPU, PPO_CPU = "reference_ppo_h200.json", "reference_ppo_epyc.json"
HOUSES = "house_study.tar.xz"


def seeds(per_seed: list[dict]) -> str:
    s = [r["seed"] for r in per_seed]
    return f"{s[0]}-{s[-1]}" if s == list(range(s[0], s[-1] + 1)) else ", ".join(map(str, s))


# ---------------------------------------------------------------------- formats
def words(v: Verdict) -> str:
    """The rule's words; a "level" whose quoted 95% interval reaches past the margin also
    gives the 90% interval it rests on."""
    out = v.words()
    if v.word == "level" and not (-v.margin < v.ci95[0] and v.ci95[1] < v.margin):
        out += f" (90% CI [{signed(v.ci90[0])}, {signed(v.ci90[1])}])"
    return out


def rate_of(arm: str) -> str:
    return arm.split("learning_rate=")[1].split(",")[0]


def method_of(arm: str) -> str:
    return arm.split("@")[0]


def cpu_of(per_seed: list[dict]) -> str:
    """The processor every chunk of every seed ran on, as "Intel Xeon (family 6, model 167)"."""
    cpus = {json.dumps(n["platform"]["cpu"], sort_keys=True) for r in per_seed for n in r["numerics"]}
    if len(cpus) != 1:
        return "several machines"
    cpu = json.loads(cpus.pop())
    name = cpu["name"].replace("(R)", "").replace(" Processor", "").strip()
    name = " ".join(w for w in name.split() if not w.endswith("-Core"))
    return f"{name} (family {cpu['family']}, model {cpu['model']})"


# ---------------------------------------------------------------------- tables
def grid_table(archives: Archives, archive: str, arms: tuple[str, ...], updates: bool = False) -> str:
    """Each arm's validation SR (what chooses), test SR and SPL over seeds; the rate each
    method's seeds' mean validation SR chooses is marked (`tuning.choose`, a method with one
    rate chooses nothing); `updates`: each seed's selected update too."""
    by_method: dict[str, dict[str, list[dict]]] = {}
    for arm in arms:
        by_method.setdefault(method_of(arm), {})[arm] = archives.results(archive, arm)
    picked = {tuning.choose(by_arm) for by_arm in by_method.values() if len(by_arm) > 1}
    header = ["method", "learning rate", "validation SR (chooses)", "test SR", "test SPL"]
    header += ["selected updates"] * updates + [""]
    rows = []
    for arm in arms:
        per_seed = archives.results(archive, arm)
        row = [method_of(arm), rate_of(arm), mean_std(values(per_seed, VALIDATION))]
        row += [mean_std(values(per_seed, m)) for m in ("SR", "SPL")]
        if updates:
            row.append(" / ".join(str(r["selected_update"]) for r in per_seed))
        row.append("**chosen**" if arm in picked else "")
        rows.append(row)
    return table(header, rows, tight=True)


def family_table(archives: Archives, family, first: str = "B - A", style: str = "pairs", b_sr: bool = True) -> str:
    """The pairs of `family`, each with its SR and SPL intervals, P(B > A) of SR, Holm's p of
    SR / SPL over the family, the MDE of SR and the rule's words on SR / SPL. style "best"
    (best against best): the IQM of B in place of B's SR."""
    n = len(family)
    holm = f"p of SR / SPL (Holm, {n} pairs)" if n > 1 else "p of SR / SPL"
    if style == "best":
        header = [first, "SR [95% CI]", "SPL [95% CI]", "IQM of B [95% bootstrap]", "P(B > A) of SR", holm]
    else:
        header = [first] + ["B's SR"] * b_sr + ["SR [95% CI]", "SPL [95% CI]", "P(B > A) of SR", holm]
    header += ["MDE of SR", "verdict, SR / SPL"]
    sr, spl = judged(archives, family, "SR"), judged(archives, family, "SPL")
    rows = []
    for pair, v, w in zip(family, sr, spl):
        a, b = pair.sides(archives, "SR")
        poi = stats.stratified_bootstrap_ci(stats.probability_of_improvement, b, a)
        row = [pair.name(archives)]
        if style == "best":
            row += [v.figures(), w.figures(), bootstrap(stats.stratified_bootstrap_ci(stats.iqm, b))]
        else:
            row += [mean_std(b)] * b_sr + [v.figures(), w.figures()]
        row += [bootstrap(poi, 2), f"{v.p:.3f} / {w.p:.3f}", f"{v.mde:.1f}", f"{words(v)} / {words(w)}"]
        rows.append(row)
    return table(header, rows)


def verdict_table(archives: Archives, rows, first: str = "B - A") -> str:
    """One row a (label, pair, metric, its family or None): the figures and the rule's words
    (Holm over the family where one is given)."""
    out = []
    for label, pair, metric, family in rows:
        family = family or (pair,)
        v = judged(archives, family, metric)[family.index(pair)]
        out.append([label or pair.name(archives), metric, v.figures(), words(v)])
    return table([first, "metric", "mean [95% CI]", "verdict"], out)


def upper_end(archives: Archives, family, what: str) -> str:
    """Where the upper end of the SR interval of `family`'s first pair (Holm over the family)
    lies against the paper's gain: "The upper end of `what`, +2.6, lies below the paper's +3.8"."""
    hi = judged(archives, family, "SR")[0].ci95[1]
    side = "below" if hi < PAPER_MARGIN else "at or above"
    return f"The upper end of {what}, {signed(hi)}, lies {side} the paper's +{PAPER_MARGIN}"


def pairs_of(archive: str, arms: tuple[str, ...], pairs) -> tuple[Pair, ...]:
    return tuple(Pair(Ref(archive, arms[i]), Ref(archive, arms[j])) for i, j in pairs)


def short(family, labels) -> tuple[Pair, ...]:
    return tuple(dataclasses.replace(p, label=label) for p, label in zip(family, labels))


# ---------------------------------------------------------------------- the PPO reference row
def label(lr: float) -> str:
    """A learning rate as the docs write it: 0.00025 -> "2.5e-4"."""
    mantissa, exponent = f"{lr:e}".split("e")
    return f"{float(mantissa):g}e{int(exponent)}"


def ppo_rates(archives: Archives) -> str:
    """The PPO reference's learning rates (the H200's five) and their mean validation SR over seeds; the chosen in bold."""
    gpu = archives.json(PPO_GPU)
    by_lr = sorted((float(lr), float(np.mean(v["val_sr"]))) for lr, v in gpu["by_lr"].items())
    best = max(by_lr, key=lambda x: x[1])[0]
    cells = [f"**{v:.1f}**" if lr == best else f"{v:.1f}" for lr, v in by_lr]
    cpu = archives.json(PPO_CPU)
    cpu_val = {float(lr): float(np.mean(v["val_sr"])) for lr, v in cpu["by_lr"].items()}
    cpu_best = max(cpu_val, key=cpu_val.get)
    out = table(["learning rate", *(label(lr) for lr, _ in by_lr)], [["validation SR (chooses)", *cells]])
    return out + (
        f"\nOn the EPYC, over its three rates ({', '.join(label(lr) for lr in sorted(cpu_val))}), validation chose "
        f"{label(cpu_best)}; on the H200, over the same three, "
        f"{label(max((lr for lr, _ in by_lr if lr in cpu_val), key=dict(by_lr).get))}.\n"
    )


def ppo_row(archives: Archives) -> str:
    """The PPO reference row's test SR and SPL beside a3c at its validated rate (the tuned
    fairness study), and the pair sampled PPO - a3c on the same test episodes of the same seeds."""
    gpu = archives.json(PPO_GPU)
    lr = label(gpu["learning_rate"])
    a3c = Ref(TUNE, Chosen((A3, A10)))
    base = a3c.results(archives)
    if [r["seed"] for r in base] != gpu["seeds"]:
        raise ValueError("the PPO reference and a3c were not run on the same seeds")
    rows = [
        [f"PPO, {lr}, {name} actions", mean_std(gpu[name]["test_sr"]), mean_std(gpu[name]["test_spl"])]
        for name in ("sampled", "greedy")
    ]
    rows.append(
        [
            f"a3c at its validated {rate_of(a3c.name(archives))} (the tuned fairness study, Xeon)",
            *(mean_std(values(base, m)) for m in ("SR", "SPL")),
        ]
    )
    out = table(["policy", "test SR", "test SPL"], rows)
    pairs = []
    for metric, key in (("SR", "test_sr"), ("SPL", "test_spl")):
        v = verdict(np.asarray(gpu["sampled"][key]) - values(base, metric), metric, PAPER_MARGIN)
        pairs.append(["sampled PPO - a3c", f"seeds {seeds(base)}", metric, v.figures(), words(v)])
    header = ["B - A", "seeds (the same test episodes)", "metric", "mean [95% CI]", "verdict"]
    return out + "\n" + table(header, pairs)


# ---------------------------------------------------------------------- the paper's question with power
# The ceiling and channels studies' pairs this page quotes (docs/ceiling.md is their page):
# each a single question, judged alone.
ORACLE, ORACLE_0 = "a3c+oracle@learning_rate=3e-4", "a3c+oracle@learning_rate=3e-4,sigma2_max=0"
S1, S2, S3, S4 = (f"channels_{s}.tar.xz" for s in ("stage1", "stage2", "stage3", "rooms"))
COMPASS = "a3c+compass@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0"
START = "a3c+startcompass@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0"
THROUGH = {
    "encoder": (C3, "a3c+oracle@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0"),
    "mlp": (
        "a3c+critic@learning_rate=3e-4,imagination_input=mlp",
        "a3c+oracle@learning_rate=3e-4,imagination_input=mlp,sigma2_max=0",
    ),
    "head": (C3, ORACLE_0),
}
CEILINGS = (
    ("today's rooms, the oracle with Eq. 7's noise", "ceiling_savn.tar.xz", ORACLE),
    ("today's rooms, the oracle without noise (`sigma2_max=0`)", "ceiling_savn_noiseoff.tar.xz", ORACLE_0),
    ("rooms with priors, the oracle with Eq. 7's noise", "ceiling_priors.tar.xz", ORACLE),
    (
        "today's rooms, machine-matched (the critic retrained on the EPYC), with the noise",
        "ceiling_savn_epyc.tar.xz",
        ORACLE,
    ),
    ("today's rooms, machine-matched, without noise", "ceiling_savn_epyc.tar.xz", ORACLE_0),
    (
        "rooms with priors, machine-matched (the critic retrained on the EPYC), with the noise",
        "ceiling_priors_epyc.tar.xz",
        ORACLE,
    ),
    ("rooms with priors, machine-matched, without noise", "ceiling_priors_noiseoff.tar.xz", ORACLE_0),
    ("rooms with priors, range 4, machine-matched, with the noise", "ceiling_range4.tar.xz", ORACLE),
    ("rooms with priors, range 4, machine-matched, without noise", "ceiling_range4_noiseoff.tar.xz", ORACLE_0),
)


def power_ceilings(archives: Archives) -> str:
    """The ceilings measured so far: a privileged oracle's SR over the critic alone, each alone."""
    rows = []
    for setting, archive, oracle in CEILINGS:
        v = judged(archives, (Pair(Ref(archive, C3), Ref(archive, oracle)),), "SR")[0]
        rows.append([setting, v.figures(), f"{v.mde:.1f}", words(v)])
    header = ["setting", "the ceiling: oracle - critic, SR [95% CI]", "MDE of SR (5 seeds)", "verdict (each alone)"]
    return table(header, rows)


def power_channels(archives: Archives) -> str:
    """Stage 2: the goal view through each channel over its base, and the plan's rule 3 (the
    mean validation SR of the selected models chooses the channel)."""
    bases = {"encoder": "a3c+critic", "mlp": "a3c+critic through `mlp`", "head": "a3c+critic"}
    rows, chooses = [], {}
    for channel, (base, oracle) in THROUGH.items():
        v = judged(archives, (Pair(Ref(S2, base), Ref(S2, oracle)),), "SR")[0]
        retrained = ", retrained" if channel == "head" else ""
        rows.append(
            [
                f"the goal view through `{channel}`{retrained} (the base: {bases[channel]})",
                v.figures(),
                f"{v.mde:.1f}",
                words(v),
            ]
        )
        chooses[channel] = float(values(archives.results(S2, oracle), VALIDATION).mean())
    header = [
        "setting (rooms with priors, range 4, the oracle without noise, stage 2)",
        "the ceiling: oracle - its base, SR [95% CI]",
        "MDE of SR (5 seeds)",
        "verdict (each alone)",
    ]
    ranked = sorted(chooses, key=chooses.get, reverse=True)
    said = ", ".join(f"`{c}` {chooses[c]:.2f}" for c in ranked)
    return table(header, rows) + (
        f"\nThe plan's rule 3 (the mean validation SR of the selected models chooses): {said}; it chose `{ranked[0]}`, "
        f"{chooses[ranked[0]] - chooses[ranked[1]]:.2f} points above `{ranked[1]}`.\n"
    )


def power_more(archives: Archives) -> str:
    """The channels study's other pairs this section quotes (rooms with priors, range 4 unless
    named; each alone), and the goal view shuffled across episodes in the noise-off oracle's policy."""
    renewed = "a compass renewed every step, through `encoder` (privileged) - critic, stage 1"
    held = "the compass of the start, held, through `encoder` (privileged) - critic, stage 1"
    through = "the goal view through `{}` (stage 2) - the start compass (stage 1)"
    stage3 = "the goal view through `head` - critic, 9000 updates (stage 3)"
    budget = "the critic at 9000 updates - the same runs at 3000 (stage 3, extended from stage 2)"
    stage4 = "the goal view through `head` - critic, today's rooms (stage 4)"
    earlier = "ceiling_savn_epyc.tar.xz"
    quoted = [
        (renewed, Ref(S1, C3), Ref(S1, COMPASS), "SR"),
        (held, Ref(S1, C3), Ref(S1, START), "SR"),
        (held, Ref(S1, C3), Ref(S1, START), "SPL"),
        *(
            (through.format(c), Ref(S1, START), Ref(S2, oracle), m)
            for c, (_, oracle) in THROUGH.items()
            for m in SR_SPL
        ),
        (stage3, Ref(S3, C3), Ref(S3, ORACLE_0), "SR"),
        (budget, Ref(S3, C3, AT_3000), Ref(S3, C3), "SR"),
        (stage4, Ref(S4, C3), Ref(S4, ORACLE_0), "SR"),
        (stage4, Ref(S4, C3), Ref(S4, ORACLE_0), "SPL"),
        (f"the same pair, an earlier run (docs/data/{earlier})", Ref(earlier, C3), Ref(earlier, ORACLE_0), "SPL"),
    ]
    rows = [(label, Pair(a, b), metric, None) for label, a, b, metric in quoted]
    out = verdict_table(archives, rows)
    shuffled = probe_condition(archives.probe("ceiling_probe_range4.json")[ORACLE_0], "shuffled")
    return out + (
        f"\nIn the range-4 noise-off oracle's policy, the goal view shuffled across episodes - as trained "
        f"(docs/data/ceiling_probe_range4.json), SR: {shuffled.figures()}: {words(shuffled)}.\n"
    )


# ---------------------------------------------------------------------- each arm at its own rate (savn)
TUNE_ARMS = (A3, A10, C3, C10, F3, F10)


def chosen(archive: str, method: str) -> Ref:
    """`method` at the rate of `RATES` its validation chose (`tuning.choose`)."""
    return Ref(archive, Chosen(tuple(f"{method}@learning_rate={r}" for r in RATES)))


def best_family(archive: str, methods: tuple[str, ...]) -> tuple[Pair, ...]:
    """Each method at the rate its validation chose, every pair of them in order (B - A, A first)."""
    return tuple(
        Pair(chosen(archive, a), chosen(archive, b), f"{b} - {a}")
        for i, a in enumerate(methods)
        for b in methods[i + 1 :]
    )


def common_family(archive: str, methods: tuple[str, ...], rate: str) -> tuple[Pair, ...]:
    arm = {m: f"{m}@learning_rate={rate}" for m in methods}
    return tuple(
        Pair(Ref(archive, arm[a]), Ref(archive, arm[b]), f"{b} - {a}")
        for i, a in enumerate(methods)
        for b in methods[i + 1 :]
    )


def rate_family(archive: str, methods: tuple[str, ...]) -> tuple[Pair, ...]:
    """Each method's 1e-3 - 3e-4, paired over its seeds."""
    return tuple(
        Pair(Ref(archive, f"{m}@learning_rate=3e-4"), Ref(archive, f"{m}@learning_rate=1e-3"), f"{m}: 1e-3 - 3e-4")
        for m in methods
    )


def iqm_of(archives: Archives, ref: Ref) -> str:
    return bootstrap(stats.stratified_bootstrap_ci(stats.iqm, values(ref.results(archives), "SR")))


SAVN = ("a3c", "a3c+critic", "a3c+foresit")


def tune_grid(archives: Archives) -> str:
    return grid_table(archives, TUNE, TUNE_ARMS)


def best_table(archives: Archives, archive: str, methods: tuple[str, ...], which: str) -> str:
    """Best against best (`best_family`), with the base's IQM at its chosen rate; `which`:
    the rates chosen, in words."""
    base = chosen(archive, methods[0])
    return (
        f"Best vs best, each arm at its chosen rate ({which}), paired over seeds {seeds(base.results(archives))}:\n\n"
        + family_table(archives, best_family(archive, methods), style="best")
        + f"\n({methods[0]}'s IQM at {rate_of(base.name(archives))}: {iqm_of(archives, base)}.)\n"
    )


def tune_best(archives: Archives) -> str:
    return best_table(archives, TUNE, SAVN, ", ".join(f"{m} {rate_of(chosen(TUNE, m).name(archives))}" for m in SAVN))


def rates_table(archives: Archives, archive: str, methods: tuple[str, ...]) -> str:
    """The pairs all at one rate (Holm over each rate's pairs), then each method's 1e-3 -
    3e-4 (validation SR, test SR, test SPL; each alone)."""
    rows = []
    for rate in RATES:
        family = common_family(archive, methods, rate)
        for pair in family:
            for metric in ("SR", "SPL"):
                rows.append((f"{pair.label}, both at {rate} (Holm, {len(family)} pairs)", pair, metric, family))
    for pair in rate_family(archive, methods):
        for metric in (VALIDATION, "SR", "SPL"):
            rows.append((pair.label, pair, metric, None))
    return verdict_table(archives, rows)


def tune_rates(archives: Archives) -> str:
    return rates_table(archives, TUNE, SAVN)


# ---------------------------------------------------------------------- the 3e-4 arms at 3x
THREE_X_ARMS = (A3, C3, F3)
THREE_X_PAIRS = pairs_of(THREE_X, (A3, F3, C3), ((0, 1), (0, 2), (2, 1)))  # the sweep's order: a3c, foresit, critic


def three_x_arms(archives: Archives) -> str:
    """Per arm: SR and SPL at 3000 and at 9000 updates (the same seeds), the change paired
    over seeds, and each seed's selected update at 9000."""
    rows = []
    for arm in THREE_X_ARMS:
        before, after = Ref(THREE_X, arm, AT_3000).results(archives), Ref(THREE_X, arm).results(archives)
        same_seeds(before, after, f"{arm} at 3000 and at 9000 updates")
        cells = [method_of(arm)]
        for m in ("SR", "SPL"):
            x, y = values(before, m), values(after, m)
            cells += [mean_std(x), mean_std(y), paired_figures(x, y)]
        cells.append(" / ".join(str(r["selected_update"]) for r in after))
        rows.append(cells)
    n = seeds(Ref(THREE_X, A3).results(archives))
    header = [f"arm (seeds {n})", "SR at 3000", "SR at 9000", "9000 - 3000, SR", "SPL at 3000", "SPL at 9000"]
    header += ["9000 - 3000, SPL", "selected updates"]
    return table(header, rows)


def three_x_pairs(archives: Archives) -> str:
    return "Pairs at 9000 updates (seeds 0-4):\n\n" + family_table(archives, THREE_X_PAIRS)


def _at_3000(pair: Pair) -> Pair:
    return Pair(dataclasses.replace(pair.a, file=AT_3000), dataclasses.replace(pair.b, file=AT_3000), pair.label)


def three_x_change(archives: Archives) -> str:
    """Each pair at 3000 and at 9000 updates, and the change of its difference seed by seed
    (judged alone)."""
    rows = []
    for pair in THREE_X_PAIRS:
        name = f"{method_of(pair.b.arm)} - {method_of(pair.a.arm)}"
        cells = [name]
        said = []
        for m in ("SR", "SPL"):
            before, after = _at_3000(pair).differences(archives, m), pair.differences(archives, m)
            cells += [
                paired_figures(np.zeros(len(before)), before),
                paired_figures(np.zeros(len(after)), after),
            ]
            v = verdict(after - before, m, PAPER_MARGIN)
            cells.append(v.figures())
            said.append(words(v))
        rows.append(cells + [" / ".join(said)])
    header = ["B - A", "SR at 3000", "SR at 9000", "change", "SPL at 3000", "SPL at 9000", "change"]
    return table(header + ["verdict on the change, SR / SPL"], rows)


def three_x_verdicts(archives: Archives) -> str:
    """The verdicts the section's words rest on: the pairs at 9000 (Holm over the three, as
    in the table), training SR over the last 250 updates, and ForeSIT at 3e-4 against a3c at
    the rate it did not choose at 3x (fair_tune_3x.tar.xz's a3c at 1e-3, the same seeds and
    test episodes, 9000 updates)."""
    f, c = THREE_X_PAIRS[0], THREE_X_PAIRS[1]
    other = Pair(Ref(TUNE_3X, A10), Ref(THREE_X, F3), "a3c+foresit@3e-4 - a3c@1e-3, both at 9000 updates")
    rows = [
        ("a3c+foresit - a3c", f, "SR", THREE_X_PAIRS),
        ("a3c+foresit - a3c", f, "SPL", THREE_X_PAIRS),
        ("a3c+foresit - a3c, the last 250 updates", f, report.TRAINING, None),
        ("a3c+critic - a3c", c, "SR", THREE_X_PAIRS),
        ("a3c+critic - a3c", c, "SPL", THREE_X_PAIRS),
        (None, other, "SR", None),
    ]
    out = verdict_table(archives, rows)
    at_3000 = judged(archives, tuple(_at_3000(p) for p in THREE_X_PAIRS), "SR")[0]
    upper = upper_end(archives, THREE_X_PAIRS, "a3c+foresit - a3c's SR interval at 9000 updates")
    return out + (
        f"\n{upper}. At 3000 updates, with Holm over the three pairs there, the same pair was "
        f"{at_3000.figures()} SR: {words(at_3000)}.\n"
    )


def three_x_rising(archives: Archives) -> str:
    """Whether the curves still rose at the end: per arm, the training SR of the last 250
    updates minus that of the 250 ending 500 updates earlier (mean over seeds), and how many
    seeds selected the last or next-to-last checkpoint."""
    rows = []
    total = chosen_late = 0
    for arm in THREE_X_ARMS:
        per_seed = Ref(THREE_X, arm).results(archives)
        rise = [
            100 * (np.mean(r["training_success_rate"][-250:]) - np.mean(r["training_success_rate"][-750:-500]))
            for r in per_seed
        ]
        late = []
        for r in per_seed:
            checkpoints = sorted(v["update"] for v in r["validation"])
            late.append(r["selected_update"] in checkpoints[-2:])
        total += len(late)
        chosen_late += sum(late)
        last = len(per_seed[0]["training_success_rate"])
        rows.append([method_of(arm), f"{signed(float(np.mean(rise)))}", f"{sum(late)} of {len(late)}"])
    header = [
        f"arm ({last} updates)",
        f"training SR, updates {last - 249}-{last} - updates {last - 749}-{last - 500} (mean over seeds)",
        "seeds that selected the last or next-to-last checkpoint",
    ]
    return (
        table(header, rows) + f"\n({chosen_late} of the {total} runs selected their last or next-to-last checkpoint.)\n"
    )


def three_x_seeds(archives: Archives, kept: tuple[int, ...] = (0, 1, 2)) -> str:
    """Each arm's mean test SR at 9000 updates over the seeds Study 5 ran (0-2; docs/mechanism.md)."""
    means = []
    for arm in THREE_X_ARMS:
        per_seed = [r for r in Ref(THREE_X, arm).results(archives) if r["seed"] in kept]
        means.append(f"{method_of(arm)} {values(per_seed, 'SR').mean():.1f}")
    which = ", ".join(map(str, kept))
    return f"Here, at 3e-4 and 9000 updates, the mean test SR over seeds {which}: {', '.join(means)}.\n"


def tune_3x(archives: Archives) -> str:
    """a3c's rate at 3x: the grid at 9000 updates, 3e-4 - 1e-3 paired (validation SR, test
    SR, test SPL), and each rate's mean validation SR without the seed that moves most."""
    grid = grid_table(archives, TUNE_3X, (A3, A10))
    pair = Pair(Ref(TUNE_3X, A10), Ref(TUNE_3X, A3), "a3c: 3e-4 - 1e-3, at 9000 updates")
    out = grid + "\n" + verdict_table(archives, [(None, pair, m, None) for m in (VALIDATION, "SR", "SPL")])
    by_rate = {rate: Ref(TUNE_3X, f"a3c@learning_rate={rate}").results(archives) for rate in RATES}
    diffs = values(by_rate["3e-4"], VALIDATION) - values(by_rate["1e-3"], VALIDATION)
    seed_out = by_rate["3e-4"][int(np.argmax(np.abs(diffs)))]["seed"]
    without = {
        rate: float(values([r for r in per_seed if r["seed"] != seed_out], VALIDATION).mean())
        for rate, per_seed in by_rate.items()
    }
    return out + (
        f"\nWithout seed {seed_out} (the largest difference of the two rates' validation SR), each rate's mean "
        f"validation SR is {without['3e-4']:.2f} at 3e-4 and {without['1e-3']:.2f} at 1e-3.\n"
    )


# ---------------------------------------------------------------------- the replication (seeds 5-9)
REPLICATION_FAMILY = (
    Pair(Ref(REPLICATION, Chosen((A3, A10))), Ref(REPLICATION, F3)),
    Pair(Ref(REPLICATION, Unchosen((A3, A10))), Ref(REPLICATION, F3)),
)  # a3c+foresit at 3e-4 against a3c at the rate validation chose (rule 1), then against the other


def replication_grid(archives: Archives) -> str:
    return grid_table(archives, REPLICATION, (A3, A10, F3), updates=True)


def replication_rates(archives: Archives) -> str:
    pair = Pair(Ref(REPLICATION, A10), Ref(REPLICATION, A3), "a3c: 3e-4 - 1e-3")
    return verdict_table(archives, [(None, pair, m, None) for m in (VALIDATION, "SR", "SPL")])


def replication_pairs(archives: Archives) -> str:
    family = REPLICATION_FAMILY
    iqm = [iqm_of(archives, Ref(REPLICATION, arm)) for arm in (A3, A10)]
    return family_table(archives, family, style="best") + f"\n(a3c's IQM of SR: {iqm[0]} at 3e-4, {iqm[1]} at 1e-3.)\n"


def replication_words(archives: Archives) -> str:
    """Rule 3: the words the rule gives the pair (best against best, then against the rate
    rule 1 did not choose), on test SR and SPL and on training SR over the last 250 updates."""
    family = REPLICATION_FAMILY
    best, other = family
    rows = [("a3c+foresit at 3e-4 - a3c at its validated rate", best, m, family) for m in ("SR", "SPL")]
    rows.append(("a3c+foresit - a3c, the last 250 updates", best, report.TRAINING, None))
    rows.append((f"a3c+foresit at 3e-4 - a3c at {rate_of(other.a.name(archives))}", other, "SR", family))
    out = verdict_table(archives, rows)
    return out + (
        f"\n{upper_end(archives, family, 'the best-against-best SR interval')} (Holm over the {len(family)} pairs "
        "for the words).\n"
    )


def replication_sets(archives: Archives) -> str:
    """The two sets side by side, each by the rule on its own (not pooled: two machines):
    seeds 0-4 (fair_3x, a3c's 3x rate chosen by fair_tune_3x) and seeds 5-9."""
    sets = (
        (THREE_X_PAIRS, 0, Ref(TUNE_3X, Chosen((A3, A10)))),
        (REPLICATION_FAMILY, 0, Ref(REPLICATION, Chosen((A3, A10)))),
    )
    rows = []
    for family, i, chooser in sets:
        pair = family[i]
        sr, spl = judged(archives, family, "SR")[i], judged(archives, family, "SPL")[i]
        per_seed = pair.b.results(archives)
        rows.append(
            [
                seeds(per_seed),
                cpu_of(per_seed),
                rate_of(chooser.name(archives)),
                f"{rate_of(pair.a.name(archives))}",
                sr.figures(),
                spl.figures(),
                f"{sr.mde:.1f}",
                f"{words(sr)} / {words(spl)}",
            ]
        )
    header = ["seeds", "machine", "a3c's rate (rule 1)", "a3c's rate in the pair", "a3c+foresit - a3c, SR", "SPL"]
    return table(header + ["MDE of SR", "verdict, SR / SPL (Holm over the set's pairs)"], rows)


# ---------------------------------------------------------------------- org
ORG_ARMS = tuple(f"{m}@learning_rate={r}" for m in ORG for r in RATES)


def org_grid(archives: Archives) -> str:
    return grid_table(archives, TUNE_ORG, ORG_ARMS)


def org_best(archives: Archives) -> str:
    rates = {rate_of(chosen(TUNE_ORG, m).name(archives)) for m in ORG}
    return best_table(archives, TUNE_ORG, ORG, f"all three {rates.pop()}" if len(rates) == 1 else "each its own")


def org_rates(archives: Archives) -> str:
    return rates_table(archives, TUNE_ORG, ORG)


def org_seeds(archives: Archives) -> str:
    """Each org arm's test SR per seed at 1e-3 (docs/mechanism.md quotes the EPYC's runs of the same arms)."""
    rows = []
    for m in ORG:
        per_seed = archives.results(TUNE_ORG, f"{m}@learning_rate=1e-3")
        rows.append([m, seed_by_seed(values(per_seed, "SR")), cpu_of(per_seed)])
    return table(["arm, at 1e-3", "test SR per seed (seeds 0-4)", "machine"], rows)


# ---------------------------------------------------------------------- the bases, the first sweep, f_w, the noise
def bases(archives: Archives) -> str:
    family = BASES_FAMILY
    a3c = values(archives.results(BASES, "a3c"), "SR")
    return family_table(archives, family, first="B - A (seeds 0-4)") + f"\n(a3c: {mean_std(a3c)}.)\n"


FIRST_PAIRS = pairs_of(FIRST, (A3, F3, C3), ((0, 1), (0, 2), (2, 1)))
FIRST_LABELS = ("a3c+foresit - a3c", "a3c+critic - a3c", "a3c+foresit - a3c+critic")


def first_arms(archives: Archives) -> str:
    rows = []
    for arm in (A3, C3, F3):
        per_seed = archives.results(FIRST, arm)
        sr, spl = values(per_seed, "SR"), values(per_seed, "SPL")
        iqm = stats.stratified_bootstrap_ci(stats.iqm, sr)
        rows.append([method_of(arm), seed_by_seed(sr), mean_std(sr), mean_std(spl), bootstrap(iqm)])
    header = ["arm (quick, Adam 3e-4, seeds 0-4)", "test SR per seed", "SR (mean ± std)", "SPL"]
    return table(header + ["IQM of SR [95% bootstrap]"], rows)


def first_pairs(archives: Archives) -> str:
    family = short(FIRST_PAIRS, FIRST_LABELS)
    return family_table(archives, family, first="paired over seeds 0-4", b_sr=False)


def first_verdicts(archives: Archives) -> str:
    """ForeSIT - a3c at 3e-4 on training SR, and seed by seed on test SR."""
    pair = dataclasses.replace(FIRST_PAIRS[0], label=FIRST_LABELS[0])
    out = verdict_table(archives, [(FIRST_LABELS[0] + ", the last 250 updates", pair, report.TRAINING, None)])
    a, b = pair.sides(archives, "SR")
    gaps = a - b
    upper = upper_end(archives, FIRST_PAIRS, "a3c+foresit - a3c's SR interval")
    return out + (
        f"\nSeed by seed, a3c's test SR is above a3c+foresit's in {int((gaps > 0).sum())} of {len(gaps)} seeds "
        f"(a3c - a3c+foresit from {gaps.min():.1f} to {gaps.max():.1f} points). {upper}.\n"
    )


def fw(archives: Archives) -> str:
    family = FW_FAMILY
    others = ", ".join(
        f"{a} {mean_std(values(archives.results(FW_ARCHIVE, a), 'SR'))}" for a in ("a3c", "a3c+critic", "a3c+foresit")
    )
    a, b = family[0].sides(archives, "SR")
    return (
        family_table(archives, family, first="B - A (seeds 0-4)")
        + f"\n({others}, all at 1e-3. {FW} is above a3c+foresit in test SR in {int((b > a).sum())} of "
        f"{len(a)} seeds.)\n"
    )


def noise(archives: Archives) -> str:
    family = NOISE_FAMILY
    labels = ("a3c at its chosen 1e-3", "a3c+critic at 3e-4", "a3c+foresit at 3e-4")
    others = "; ".join(
        f"{label}: {mean_std(values(archives.results(NOISE_ARCHIVE, a), 'SR'))}"
        for label, a in zip(labels, ("a3c", C3, F3))
    )
    return family_table(archives, family, first="B - A (seeds 0-4)") + f"\n({others}.)\n"


# ---------------------------------------------------------------------- the f_w probes
FIT_COLUMNS = (
    ("R^2 online f_w", "r2_over_mean"),
    ("category mean", "category_r2_over_mean"),
    ("s_0", "identity_r2_over_mean"),
    ("ridge on [s_0 : g]", "ridge_r2_over_mean"),
    ("offline f_w", "offline_r2_over_mean"),
)


def probe_fit(archives: Archives) -> str:
    rows = []
    for r in archives.probe(PROBE)[F3]:
        f = r["items"]["fit"]
        shares = r["items"]["subgoal"]["shares"]
        rows.append([str(r["seed"]), f"{100 * shares[0]:.0f}%", *(f"{f[k]:.2f}" for _, k in FIT_COLUMNS)])
    episodes = [r["items"]["subgoal"]["episodes"] for r in archives.probe(PROBE)[F3]]
    return table(["seed", "t*/T < 0.2", *(c for c, _ in FIT_COLUMNS)], rows) + (
        f"\n(R^2 over the fit items' mean, on the held-out items; {min(episodes)} to {max(episodes)} successful "
        "episodes per seed.)\n"
    )


def _option_label(option: str) -> str:
    return {
        "as trained": "as trained (Adam 1e-3, 5 epochs, M 32, batch 1)",
        "sgd, lr 1e-2 (Algorithm 1)": "sgd 1e-2",
    }.get(option, option)


def probe_options(archives: Archives) -> str:
    per_seed = archives.probe(PROBE)[F3]
    options = list(per_seed[0]["items"]["fit_options"])
    rows = [[str(r["seed"]), *(f"{r['items']['fit_options'][o]:.2f}" for o in options)] for r in per_seed]
    return table(["seed", *map(_option_label, options)], rows)


def probe_summary(archives: Archives) -> str:
    """What the two tables above give, seed by seed: each R^2 against the category mean's,
    each replayed option against the procedure as trained, and the kept optimiser state
    against a fresh one at each flush."""
    per_seed = archives.probe(PROBE)[F3]
    fit = [r["items"]["fit"] for r in per_seed]
    n = len(per_seed)
    rows = []
    for label, key in (FIT_COLUMNS[3], FIT_COLUMNS[4], FIT_COLUMNS[0], FIT_COLUMNS[2]):
        d = np.array([f[key] - f["category_r2_over_mean"] for f in fit])
        rows.append(
            [f"{label} - category mean", f"{int((d > 0).sum())} of {n}", span(d, 3), signed(float(d.mean()), 3)]
        )
    options = [r["items"]["fit_options"] for r in per_seed]
    offline = np.array([f["offline_r2_over_mean"] for f in fit])
    trained = np.array([o["as trained"] for o in options])
    rows.append(
        [
            "offline f_w - as trained",
            f"{int((offline > trained).sum())} of {n}",
            span(offline - trained, 3),
            signed(float((offline - trained).mean()), 3),
        ]
    )
    for option in list(options[0])[1:]:
        fresh = "lr 3e-4" if option == "state kept, lr 3e-4" else "as trained"
        d = np.array([o[option] - o[fresh] for o in options])
        rows.append(
            [
                f"{_option_label(option)} - {fresh}",
                f"{int((d > 0).sum())} of {n}",
                span(d, 3),
                signed(float(d.mean()), 3),
            ]
        )
    header = ["R^2 over the fit items' mean, B - A", "seeds where B > A", "per seed", "mean"]
    kept = []
    for option, fresh in (("state kept", "as trained"), ("state kept, lr 3e-4", "lr 3e-4")):
        d = np.array([o[option] - o[fresh] for o in options])
        sd = float(np.std(d, ddof=1))
        kept.append(f"SD {sd:.3f}, MDE {stats.minimum_detectable_effect(sd, len(d)):.3f} ({option} - {fresh})")
    return table(header, rows) + (
        f"\n(The kept state's differences over the {n} paired seeds: {'; '.join(kept)}: the R^2 difference "
        "these seeds detect with 80% power.)\n"
    )


ITAU = (
    ("i_tau shuffled across episodes, the noise off", "shuffled, noise off"),
    ("i_tau shuffled across episodes, the training-end noise", "shuffled"),
    ("from an untrained f_w", "untrained f_w"),
)


def _itau_rows(archives: Archives, name: str, arm: str, where: str) -> list[list[str]]:
    per_seed = archives.probe(name)[arm]
    rows = []
    for label, key in ITAU:
        v = probe_condition(per_seed, key)
        rows.append([f"{label} - as trained", where, v.figures(), words(v)])
    return rows


def _signal(archives: Archives, name: str, arm: str) -> str:
    share = [100 * r["items"]["signal"]["signal_share"] for r in archives.probe(name)[arm]]
    return f"{min(share):.0f}-{max(share):.0f}%"


def probe_itau(archives: Archives) -> str:
    """The policy's test SR with i_tau changed, against as trained, paired over seeds."""
    rows = _itau_rows(archives, PROBE, F3, "Eq. 6's placement")
    return table(["B - A (test SR, seeds 0-4)", "arm", "mean [95% CI]", "verdict"], rows) + (
        f"\n(i_tau's signal: {_signal(archives, PROBE, F3)} of its variance at the training-end noise, over the seeds.)\n"
    )


def noise_probe(archives: Archives) -> str:
    """The probes of i_tau with the noise inside f_w's input, beside Eq. 6's placement."""
    rows = _itau_rows(archives, PROBE_NOISE, NOISE, "Algorithm 1's placement") + _itau_rows(
        archives, PROBE, F3, "Eq. 6's placement"
    )
    out = table(["B - A (test SR, seeds 0-4)", "arm", "mean [95% CI]", "verdict"], rows)
    fit = [r["items"]["fit"] for r in archives.probe(PROBE_NOISE)[NOISE]]
    over = np.array([f["r2_over_category"] for f in fit])
    ridge = np.array([f["ridge_r2_over_mean"] - f["category_r2_over_mean"] for f in fit])
    return out + (
        f"\nWith the noise inside f_w's input: the online f_w's R^2 over the target category's mean is "
        f"{span(over, 3)} ({int((over < 0).sum())} of {len(over)} seeds below 0); ridge on [s_0 : g] - the "
        f"category mean is {span(ridge, 3)} ({int((ridge > 0).sum())} of {len(ridge)} seeds above 0).\n"
    )


# ---------------------------------------------------------------------- In brief
PRIORS = "priors.md#the-papers-question-there-5-seeds-2026-11-27"  # links from docs/results.md
HOUSES_SECTION = "houses.md#does-imagination-help-on-long-paths-in-houses-the-mechanism-study-repeated"


def _section(anchor: str, page: str = FAIR_PAGE) -> str:
    """A link from results.md to a section of one of its studies' pages."""
    return f"{page.removeprefix('docs/')}#{anchor}"


TUNED = _section("fairness-each-arm-at-its-own-validated-learning-rate-5-seeds-2026-11-27")
THREE_X_SECTION = _section("fairness-the-three-arms-at-3e-4-for-3x-the-budget-5-seeds-2026-11-27")
REPLICATION_SECTION = _section("replication-the-3x-pair-on-fresh-seeds-seeds-5-9-2026-11-29", REPLICATION_PAGE)
ORG_SECTION = _section("fairness-on-org-orgs-arms-at-their-own-validated-learning-rates-5-seeds-2026-11-27")
BASES_SECTION = _section(
    "fairness-the-base-with-savns-value-head-and-with-the-papers-one-step-td-advantage-5-seeds-2026-11-27"
)
FW_SECTION = _section("fairness-a-better-fitted-f_w-as-an-arm-5-seeds-2026-11-27")
NOISE_SECTION = _section("fairness-algorithm-1s-noise-placement-as-an-arm-5-seeds-2026-11-27")


PRIORS_SAVN, PRIORS_ORG = "priors_savn.tar.xz", "priors_org.tar.xz"
PRIORS_SAVN_FAMILY = pairs_of(PRIORS_SAVN, ("a3c", C3, F3), ((0, 1), (0, 2), (1, 2)))
PRIORS_ORG_FAMILY = pairs_of(PRIORS_ORG, ORG, ((0, 1), (0, 2), (1, 2)))
HOUSES_FAMILY = pairs_of(HOUSES, SAVN, ((0, 1), (0, 2), (1, 2)))
BASES_FAMILY = pairs_of(BASES, ("a3c", "a3c@value_head=linear", "a3c@gae_lambda=0"), ((0, 1), (0, 2)))
FW_FAMILY = tuple(Pair(Ref(FW_ARCHIVE, a), Ref(FW_ARCHIVE, FW)) for a in ("a3c+foresit", "a3c", "a3c+critic"))
NOISE_FAMILY = tuple(Pair(Ref(NOISE_ARCHIVE, a), Ref(NOISE_ARCHIVE, NOISE)) for a in (F3, C3, "a3c"))
TUNED_FAMILY = best_family(TUNE, SAVN)
AT_1E3_FAMILY = common_family(TUNE, SAVN, "1e-3")
ORG_FAMILY = best_family(TUNE_ORG, ORG)


@dataclasses.dataclass(frozen=True)
class Brief:
    """A row of the "In brief" tables: `pair` (the `index`-th of `family`, Holm over the
    family; None: judged alone) on `metric`."""

    label: str
    scope: str
    family: tuple
    index: int
    metric: str
    section: str
    holm: bool = True


def _briefs(label, scope, family, index, metrics, section, holm=True) -> list[Brief]:
    return [Brief(label, scope, family, index, m, section, holm and m != report.TRAINING) for m in metrics]


ROOMS, ROOMS_9000 = "rooms, 3000, 0-4 (Xeon)", "rooms, 9000, 0-4 (Xeon)"
IN_BRIEF: tuple[Brief, ...] = (
    *_briefs("a3c+foresit - a3c, each at its validated rate", ROOMS, TUNED_FAMILY, 1, ("SR", "SPL"), TUNED),
    *_briefs("a3c+foresit - a3c+critic, each at its validated rate", ROOMS, TUNED_FAMILY, 2, ("SR",), TUNED),
    *_briefs("a3c+foresit - a3c, both at quick's 1e-3", ROOMS, AT_1E3_FAMILY, 1, ("SR", "SPL"), TUNED),
    *_briefs(
        "a3c+org+critic - a3c+org, each at its validated rate (1e-3)",
        "org, " + ROOMS,
        ORG_FAMILY,
        0,
        ("SR", "SPL"),
        ORG_SECTION,
    ),
    *_briefs(
        "a3c+org+foresit - a3c+org, each at its validated rate (1e-3)",
        "org, " + ROOMS,
        ORG_FAMILY,
        1,
        ("SR", "SPL"),
        ORG_SECTION,
    ),
    *_briefs(
        "a3c+org+foresit - a3c+org+critic, each at its validated rate (1e-3)",
        "org, " + ROOMS,
        ORG_FAMILY,
        2,
        ("SR", "SPL"),
        ORG_SECTION,
    ),
    *_briefs(
        "a3c+foresit - a3c, both at 3e-4", ROOMS_9000, THREE_X_PAIRS, 0, ("SR", "SPL", report.TRAINING), THREE_X_SECTION
    ),
    *_briefs(
        "a3c+foresit@3e-4 - a3c at its validated rate (3e-4)",
        "rooms, 9000, 5-9 (EPYC)",
        REPLICATION_FAMILY,
        0,
        ("SR", "SPL", report.TRAINING),
        REPLICATION_SECTION,
    ),
    *_briefs("a3c@value_head=linear - a3c (SAVN's value head)", ROOMS, BASES_FAMILY, 0, ("SR",), BASES_SECTION),
    *_briefs("a3c+foresit@imagination_lr=3e-4 - a3c+critic, both at 1e-3", ROOMS, FW_FAMILY, 2, ("SR",), FW_SECTION),
    *_briefs(
        "Algorithm 1's noise placement - Eq. 6's, a3c+foresit at 3e-4", ROOMS, NOISE_FAMILY, 0, ("SR",), NOISE_SECTION
    ),
    *_briefs("Algorithm 1's noise placement - a3c+critic at 3e-4", ROOMS, NOISE_FAMILY, 1, ("SR",), NOISE_SECTION),
    *_briefs(
        "a3c+foresit at 3e-4 - a3c at 1e-3", "rooms with priors, 3000, 0-4", PRIORS_SAVN_FAMILY, 1, ("SR",), PRIORS
    ),
    *_briefs(
        "a3c+foresit - a3c+critic, both at 3e-4",
        "rooms with priors, 3000, 0-4",
        PRIORS_SAVN_FAMILY,
        2,
        ("SR", "SPL"),
        PRIORS,
    ),
    *_briefs("a3c+org+foresit - a3c+org", "rooms with priors, org, 3000, 0-4", PRIORS_ORG_FAMILY, 1, ("SR",), PRIORS),
    *_briefs(
        "a3c+org+foresit - a3c+org+critic", "rooms with priors, org, 3000, 0-4", PRIORS_ORG_FAMILY, 2, ("SR",), PRIORS
    ),
)


def briefs_table(archives: Archives, briefs) -> str:
    """One row a `Brief`: the pair's figures and the rule's words, Holm over its family as
    the section whose table it links to applies it."""
    rows = []
    for b in briefs:
        if b.holm and len(b.family) > 1:
            v = judged(archives, b.family, b.metric)[b.index]
            scope = f"{b.scope}; Holm over {len(b.family)} pairs"
        else:
            v = judged(archives, (b.family[b.index],), b.metric)[0]
            scope = b.scope
        rows.append([f"[{b.label}]({b.section})", scope, b.metric, v.figures(), words(v)])
    return table(["B - A", "where, how long, which seeds", "metric", "mean [95% CI]", "verdict"], rows)


def in_brief(archives: Archives) -> str:
    """The "In brief" section's archived comparisons (the links name each one's section)."""
    return briefs_table(archives, IN_BRIEF)


def houses_brief(archives: Archives) -> str:
    """The house study's arms (SR, SPL, and SR on the episodes whose shortest path is at
    least 20 actions) and its three pairs, Holm over the three as in houses.md."""
    rows = []
    for arm in SAVN:
        per_seed = archives.results(HOUSES, arm)
        far = [r["selected"]["overall"]["SR>=20"] for r in per_seed]
        rows.append([arm, mean_std(values(per_seed, "SR")), mean_std(values(per_seed, "SPL")), mean_std(far)])
    header = ["arm (houses, 12,000 updates, seeds 0-4)", "SR (mean ± std)", "SPL (mean ± std)", "SR on L^g >= 20"]
    briefs = [
        b
        for i in range(3)
        for b in _briefs(
            HOUSES_FAMILY[i].name(archives),
            "houses, 12,000, 0-4 (H100)",
            HOUSES_FAMILY,
            i,
            ("SR", "SPL"),
            HOUSES_SECTION,
        )
    ]
    return table(header, rows) + "\n" + briefs_table(archives, briefs)


def _page(name: str) -> str:
    """The file that holds a block: results.md's own, or its study's page."""
    for prefix, page in (
        ("results-fair-", FAIR_PAGE),
        ("results-replication-", REPLICATION_PAGE),
        ("results-ppo", PPO_PAGE),
    ):
        if name.startswith(prefix):
            return page
    return RESULTS


BLOCKS = {
    name: (_page(name), function)
    for name, function in {
        "results-in-brief": in_brief,
        "results-in-brief-houses": houses_brief,
        "results-ppo-rates": ppo_rates,
        "results-power-ceilings": power_ceilings,
        "results-power-channels": power_channels,
        "results-power-more": power_more,
        "results-ppo": ppo_row,
        "results-fair-tune-grid": tune_grid,
        "results-fair-tune-best": tune_best,
        "results-fair-tune-rates": tune_rates,
        "results-fair-3x-arms": three_x_arms,
        "results-fair-3x-pairs": three_x_pairs,
        "results-fair-3x-change": three_x_change,
        "results-fair-3x-verdicts": three_x_verdicts,
        "results-fair-3x-rising": three_x_rising,
        "results-fair-3x-seeds": three_x_seeds,
        "results-fair-tune-3x": tune_3x,
        "results-replication-grid": replication_grid,
        "results-replication-rates": replication_rates,
        "results-replication-pairs": replication_pairs,
        "results-replication-words": replication_words,
        "results-replication-sets": replication_sets,
        "results-fair-org-grid": org_grid,
        "results-fair-org-best": org_best,
        "results-fair-org-rates": org_rates,
        "results-fair-org-seeds": org_seeds,
        "results-fair-bases": bases,
        "results-fair-first-arms": first_arms,
        "results-fair-first-pairs": first_pairs,
        "results-fair-first-verdicts": first_verdicts,
        "results-fair-probe-fit": probe_fit,
        "results-fair-probe-options": probe_options,
        "results-fair-probe-summary": probe_summary,
        "results-fair-probe-itau": probe_itau,
        "results-fair-fw": fw,
        "results-fair-noise": noise,
        "results-fair-noise-probe": noise_probe,
    }.items()
}
