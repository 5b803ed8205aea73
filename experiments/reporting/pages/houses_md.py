"""docs/houses.md's generated blocks: the mechanism study repeated in houses (a3c, a3c+critic,
a3c+foresit; `--preset house`, seeds 0-4), read from docs/data/house_study.tar.xz: the arms and
pairs, the pairs by path length, what the archive's probe and failure reports and the arms'
diagnostics give, the validation curves, and what five seeds can tell.

Every verdict word is `verdicts.verdict`'s. The three pairs are one family on each metric
(Holm, as docs/houses.md's robust table declares); the pairs per bucket of L^g, the probe's
conditions and the rest are judged alone. The sections on the preset's calibration runs and
on how a3c fails (runs/house_cal/, runs/quick) were not archived: their figures stay
hand-written, marked so.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from experiments.reporting import report, stats
from experiments.reporting.pages.common import (
    alone,
    bootstrap,
    by_pair,
    cells,
    differences,
    figures,
    mean_std,
    probe_condition,
    said,
    seed_by_seed,
    span,
    table,
)
from experiments.reporting.registry import Archives
from experiments.reporting.verdicts import Verdict

ARCHIVE = "house_study.tar.xz"
A3C, CRITIC, FORESIT = ARMS = ("a3c", "a3c+critic", "a3c+foresit")
PAIRS = [(A3C, CRITIC), (A3C, FORESIT), (CRITIC, FORESIT)]
NAMES = {
    (A3C, CRITIC): "a3c+critic - a3c (the critic's cost)",
    (A3C, FORESIT): "a3c+foresit - a3c",
    (CRITIC, FORESIT): "a3c+foresit - a3c+critic (the imagination, the critic held)",
}
FAILURES = {A3C: "failures_a3c.json", CRITIC: "failures_critic.json", FORESIT: "failures_foresit.json"}
EXPLAINED_VARIANCE = "losses/explained_variance"


def results(archives: Archives) -> dict[str, list[dict]]:
    return archives.sweep(ARCHIVE, ARMS)


def overall(per_seed: list[dict], column: str) -> np.ndarray:
    return np.array([report.rate(r["selected"]["overall"][column]) for r in per_seed])


def judged(archives: Archives) -> dict[str, dict[tuple[str, str], Verdict]]:
    """{metric: {pair: the rule's verdict}}, Holm over the three pairs of each metric."""
    return by_pair(results(archives), PAIRS)


def study_table(archives: Archives) -> str:
    """Each arm's SR, SPL and SR on the long paths (mean ± sample std over seeds), then the
    three pairs' SR and SPL with the rule's words; each arm's SR per seed below."""
    res, words = results(archives), judged(archives)
    rows = [[arm, *(mean_std(overall(res[arm], c)) for c in ("SR", "SPL", "SR>=10", "SR>=20")), "", ""] for arm in ARMS]
    for pair in PAIRS:
        sr, spl = words["SR"][pair], words["SPL"][pair]
        rows.append([NAMES[pair], sr.figures(), spl.figures(), "", "", sr.words(), spl.words()])
    per_seed = ", ".join(f"{arm} {seed_by_seed(overall(res[arm], 'SR'))}" for arm in ARMS)
    header = ["paired over seeds 0-4", "SR", "SPL", "SR on L^g >= 10", "SR on L^g >= 20", "verdict, SR", "verdict, SPL"]
    return table(header, rows, tight=True) + (
        "\n(mean ± sample std over seeds; differences with their 95% paired t interval; each verdict is the "
        f"rule's on its metric, Holm over the three pairs.) Per seed, test SR: {per_seed}.\n"
    )


def by_length(archives: Archives, base: str, other: str) -> list[tuple[str, int, Verdict]]:
    """Per bucket of L^g: (bucket, its test episodes over base's seeds, the rule's verdict
    on `other` - `base`'s SR there, seed by seed), as `report.paired_by_length` pairs them."""
    res = results(archives)
    out = []
    for bucket, episodes, _, _ in report.paired_by_length(res, base, other):
        diffs = [
            report.rate(b["selected"]["by_length"][bucket]["SR"])
            - report.rate(a["selected"]["by_length"][bucket]["SR"])
            for a, b in zip(res[base], res[other])
        ]
        out.append((bucket, episodes, alone(diffs, "SR")))
    return out


def bucket_mean_std(per_seed: list[dict], bucket: str) -> str:
    """SR in a bucket over the seeds with episodes in it (`report.by_length_markdown`'s)."""
    x = np.array([report.rate(r["selected"]["by_length"][bucket]["SR"]) for r in per_seed])
    x = x[~np.isnan(x)]
    return "n/a" if not len(x) else f"{x.mean():.1f}" + (f" ± {x.std(ddof=1):.1f}" if len(x) > 1 else "")


def by_length_table(archives: Archives) -> str:
    """Per bucket of L^g: each arm's SR, then a3c+foresit against a3c+critic and against
    a3c, seed by seed, with the rule's words."""
    res = results(archives)
    critic, a3c = by_length(archives, CRITIC, FORESIT), by_length(archives, A3C, FORESIT)
    rows = []
    for (bucket, episodes, vc), (_, _, va) in zip(critic, a3c):
        means = [bucket_mean_std(res[arm], bucket) for arm in ARMS]
        rows.append([bucket, str(episodes), *means, *cells(vc), *cells(va)])
    header = ["L^g", "test episodes (5 seeds)", *ARMS, "a3c+foresit - a3c+critic", "verdict", "a3c+foresit - a3c"]
    return table(header + ["verdict"], rows)


def _word_counts(verdicts) -> str:
    counts = Counter(v.word for v in verdicts)
    return ", ".join(f"{word} in {n}" for word, n in counts.most_common())


def readings(archives: Archives) -> str:
    """The study's pairs, the probe and the failures in words, from the archive."""
    res, words = results(archives), judged(archives)
    held = [v for _, _, v in by_length(archives, CRITIC, FORESIT)]
    cost = by_length(archives, A3C, CRITIC)
    critic_cost = words["SR"][A3C, CRITIC]
    share = 100 * critic_cost.diff / np.mean(overall(res[A3C], "SR"))
    ev = {arm: report.values(res[arm], EXPLAINED_VARIANCE) for arm in (A3C, CRITIC)}
    ev_diff = differences(res, A3C, CRITIC, EXPLAINED_VARIANCE)
    ev_pair = stats.paired(np.zeros_like(ev_diff), ev_diff)
    failed = {
        arm: [100 * r["all"]["failed Done"] for r in archives.member(ARCHIVE, f"house_study/{name}")["methods"][arm]]
        for arm, name in FAILURES.items()
    }
    probe = archives.member(ARCHIVE, "house_study/probe.json")["methods"][FORESIT]

    def condition(name):
        return probe_condition(probe, name)

    over = [r["items"]["fit"]["r2_over_category"] for r in probe]
    signal = [100 * r["items"]["signal"]["signal_share"] for r in probe]
    late = [100 * r["items"]["subgoal"]["shares"][-1] for r in probe]
    at_done = [100 * r["items"]["subgoal"]["at_done"] for r in probe]
    last = sum(r["selected_update"] == r["validation"][-1]["update"] for arm in ARMS for r in res[arm])
    seeds = sum(len(res[arm]) for arm in ARMS)
    diffs = [v.diff for v in held]
    return (
        f"- **The imagination, the critic held, by path length** (a3c+foresit - a3c+critic, SR per bucket): "
        f"{span(diffs, 1)} points over the {len(held)} buckets; the rule's words: {_word_counts(held)}.\n"
        f"- **The critic's cost** (a3c+critic - a3c): {said(critic_cost, holm=True)}, {share:.0f}% of a3c's SR; "
        "per bucket of L^g: " + ", ".join(f"{b} {v.words()}" for b, _, v in cost) + ".\n"
        f"- **The value baseline**: the last chunk's explained variance, mean over seeds, a3c+critic "
        f"{np.mean(ev[CRITIC]):.2f} and a3c {np.mean(ev[A3C]):.2f}; a3c+critic - a3c "
        f"{figures(ev_pair, 2)} (no margin is declared for it: "
        "no verdict word).\n"
        f"- **Wrong Dones** (`experiments.failures`, the archive's `failures_*.json`): a failed Done ends "
        + ", ".join(f"{span(failed[arm], 0, False)}% of {arm}'s test episodes" for arm in (A3C, CRITIC, FORESIT))
        + " (per seed).\n"
        f"- **i_tau** (`experiments.probe`, each seed's selected model, 100 test episodes per type of the target's "
        f"room), SR against the trained condition: shuffled across episodes, {said(condition('shuffled'))}; the "
        f"noise off, {said(condition('noise off'))}; from an untrained f_w, {said(condition('untrained f_w'))}.\n"
        f"- **f_w's sub-goal**: held-out R^2 of f_w over the category mean {span(over)}, above 0 on "
        f"{sum(x > 0 for x in over)} of {len(over)} seeds; i_tau's signal {span(signal, 0, False)}% of its "
        f"variance; t*/T in 0.8-1.0 in {span(late, 0, False)}% of the successful training episodes (the Done "
        f"step's own state in {span(at_done, 0, False)}%).\n"
        f"- **The selected model** is the last one evaluated in {last} of {seeds} seeds.\n"
    )


CURVE_UPDATES = (2000, 4000, 6000, 8000, 10000, 12000)


def validation_table(archives: Archives) -> str:
    """Each arm's validation SR at every other evaluation (mean ± std over seeds)."""
    res = results(archives)
    rows = []
    for arm in ARMS:
        at = {u: [] for u in CURVE_UPDATES}
        for r in res[arm]:
            for v in r["validation"]:
                if v["update"] in at:
                    at[v["update"]].append(report.rate(v["SR"]))
        rows.append([arm, *(mean_std(at[u]) for u in CURVE_UPDATES)])
    return table(["validation SR at update", *(f"{u:,}" for u in CURVE_UPDATES)], rows)


def robust_table(archives: Archives) -> str:
    """`experiments.compare`'s robust statistics of SR for the three pairs (IQM with its
    stratified-bootstrap interval, P(B > A), Holm's p, the MDE), then the rule's words."""
    res = results(archives)
    _, out = report.paired_report(res, PAIRS, ["SR", "SPL"])
    rows = []
    for a, b in PAIRS:
        r = out[f"{b} - {a}"]["robust"]["SR"]
        poi = r["probability_of_improvement"]
        rows.append(
            [f"{b} - {a}", bootstrap(r["iqm_a"]), bootstrap(r["iqm_b"]), bootstrap(poi, 2)]
            + [f"{r['p_holm']:.3f}", f"{r['mde']:.1f}"]
        )
    words = judged(archives)["SR"]
    sentences = "; ".join(f"{NAMES[p]}, {said(words[p], holm=True)}" for p in PAIRS)
    header = ["B - A (SR)", "IQM of A", "IQM of B", "P(B > A)", "p (Holm)", "MDE"]
    return table(header, rows) + f"\nThe rule's words on SR, Holm over the three pairs: {sentences}.\n"


BLOCKS = {
    "houses-study": ("docs/houses.md", study_table),
    "houses-by-length": ("docs/houses.md", by_length_table),
    "houses-readings": ("docs/houses.md", readings),
    "houses-validation": ("docs/houses.md", validation_table),
    "houses-robust": ("docs/houses.md", robust_table),
}
