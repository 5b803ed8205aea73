"""docs/priors.md's generated blocks: the paper's question in rooms with priors (savn and org,
seeds 0-4), ORG's control, the probes, the study's answers, and what the foresight tool
measured there.

Read from docs/data's priors_savn.tar.xz, priors_org.tar.xz, priors_org_control.tar.xz,
priors_probe_{savn,org}.json, foresight_{today,priors}.json, and, for the same pairs in
today's rooms, fair_tune.tar.xz, fair_tune_org.tar.xz and fair_probe_lr3e-4.json. Every
verdict word is `verdicts.verdict`'s: the three pairs of a setup are one family on each
metric (Holm, as the tables' p column says); everything else is judged alone.

The archives' members and docs/data's JSON files are read by `registry.Archives`; the
formats and the Holm family's verdicts are `pages.common`'s.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import stats as scipy_stats

from experiments.reporting import report
from experiments.reporting.pages.common import (
    alone,
    bootstrap,
    by_pair,
    differences,
    gain,
    interval,
    mean_std,
    probe_condition,
    said,
    signed,
    span,
    table,
)
from experiments.reporting.registry import Archives, values

SAVN = "priors_savn.tar.xz"
ORG = "priors_org.tar.xz"
CONTROL = "priors_org_control.tar.xz"
TODAY = "fair_tune.tar.xz"  # today's rooms, savn: each arm at 3e-4 and 1e-3
TODAY_ORG = "fair_tune_org.tar.xz"
PROBE_SAVN, PROBE_ORG, PROBE_TODAY = "priors_probe_savn.json", "priors_probe_org.json", "fair_probe_lr3e-4.json"
FORESIGHT_TODAY, FORESIGHT_PRIORS = "foresight_today.json", "foresight_priors.json"

SAVN_ARMS = ("a3c", "a3c+critic@learning_rate=3e-4", "a3c+foresit@learning_rate=3e-4")
ORG_ARMS = ("a3c+org", "a3c+org+critic", "a3c+org+foresit")
# The same arm in today's rooms' tune archive: quick's rate, 1e-3, where the name gives none.
QUICK_RATE = "@learning_rate=1e-3"
LONG = "SR>=5"


# ---------------------------------------------------------------------- the paper's question there
class Setup(NamedTuple):
    archive: str
    arms: tuple[str, str, str]  # base, critic, foresit
    today: str  # today's rooms' tune archive
    probe: str


SETUPS = {"savn": Setup(SAVN, SAVN_ARMS, TODAY, PROBE_SAVN), "org": Setup(ORG, ORG_ARMS, TODAY_ORG, PROBE_ORG)}


def pairs_of(arms) -> list[tuple[str, str]]:
    base, critic, foresit = arms
    return [(base, critic), (base, foresit), (critic, foresit)]


def pairs_table(archives: Archives, setup: str) -> str:
    """Each pair of the setup's three arms: B's SR, the SR and SPL intervals, P(B > A), Holm's
    p and the MDE of SR (`experiments.compare`'s), and the rule's words on SR and on SPL."""
    s = SETUPS[setup]
    results = archives.sweep(s.archive, s.arms)
    pairs = pairs_of(s.arms)
    _, out = report.paired_report(results, pairs, ["SR", "SPL"])
    words = by_pair(results, pairs)
    rows = []
    for a, b in pairs:
        r = out[f"{b} - {a}"]["robust"]["SR"]
        poi = r["probability_of_improvement"]
        sr, spl = words["SR"][a, b], words["SPL"][a, b]
        rows.append(
            [f"{b} - {a}", mean_std(values(results[b], "SR")), sr.figures(), spl.figures(), bootstrap(poi, 2)]
            + [f"{r['p_holm']:.3f}", f"{r['mde']:.1f}", sr.words(), spl.words()]
        )
    header = ["B - A (seeds 0-4)", "B's SR", "SR [95% CI]", "SPL [95% CI]", "P(B > A)", "p (Holm, 3 pairs)", "MDE"]
    base = results[s.arms[0]]
    note = f"{s.arms[0]}: {mean_std(values(base, 'SR'))} SR"
    if setup == "org":
        note += f", {np.mean(values(base, 'SPL')):.1f} SPL"
    return table(header + ["verdict, SR", "verdict, SPL"], rows) + (
        f"\n({note}. P(B > A), p and the MDE are SR's; each verdict is the rule's on its metric, Holm over "
        "the three pairs of that metric.)\n"
    )


def today_arm(arm: str) -> str:
    return arm if "@" in arm else arm + QUICK_RATE


def readings(archives: Archives, setup: str) -> str:
    """The setup's pairs in words: the rule's verdicts (Holm over the three pairs), the long
    paths (L^g >= 5), the same pairs in today's rooms (each arm at the rate today's tune
    chose), and each arm's SR here and there."""
    s = SETUPS[setup]
    results = archives.sweep(s.archive, s.arms)
    base, critic, foresit = s.arms
    sr, spl = by_pair(results, pairs_of(s.arms)).values()
    today_results = {a: archives.results(s.today, today_arm(a)) for a in s.arms}

    def today_pair(a, b, metric):
        return alone(differences(today_results, a, b, metric), metric)

    def long(a, b):
        return alone(differences(results, a, b, LONG), LONG)

    def block(a, b, title, today_long):
        negative = int(np.sum(differences(results, a, b, "SR") < 0))
        lines = [
            f"- **{title}** ({b} - {a}): {said(sr[a, b], holm=True)} (negative on {negative} of "
            f"{len(results[a])} seeds); {said(spl[a, b], holm=True)}.",
            f"  - On the long paths (L^g >= 5): {said(long(a, b), 'SR')}.",
            f"  - In today's rooms, {today_arm(b)} - {today_arm(a)} (docs/data/{s.today}, seeds 0-4): "
            f"{said(today_pair(a, b, 'SR'))}"
            + (f"; on the long paths {said(today_pair(a, b, LONG), 'SR')}" if today_long else "")
            + ".",
        ]
        return lines

    lines = [
        *block(critic, foresit, "The imagination, the critic held", setup == "org"),
        *block(base, foresit, "ForeSIT against its base", setup == "org"),
        f"- **The attention critic alone against the base** ({critic} - {base}): {said(sr[base, critic], holm=True)}; "
        f"{said(spl[base, critic], holm=True)}.",
    ]
    here_there = ", ".join(
        f"{arm} {np.mean(values(results[arm], 'SR')):.1f} here, {np.mean(values(today_results[arm], 'SR')):.1f} there"
        for arm in s.arms
    )
    lines.append(
        f"- **Each arm's SR here and in today's rooms** (docs/data/{s.today}, the same arm and rate; two "
        f"environments, unpaired, so no verdict): {here_there}."
    )
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------- ORG's control
def control(archives: Archives) -> dict:
    """a3c (sampled) and a3c+org's selected models played with sampled actions, per layout
    ("today", "priors"): {layout: {"a3c": [overall per seed], "a3c+org": [...]}} by seed."""
    sampled = archives.member(CONTROL, "priors_org_control/org_sampled.json")
    out = {}
    for layout, folder in (("today", "org_control"), ("priors", "org_control_priors")):
        base = archives.member(CONTROL, f"priors_org_control/{folder}/methods/a3c/results.json")["results"]
        by_seed = {r["seed"]: r["selected"]["overall"] for r in base}
        graph = {r["seed"]: r["overall"] for r in sampled[layout]}
        if sorted(by_seed) != sorted(graph):
            raise ValueError(f"{CONTROL}: a3c and a3c+org were not played on the same seeds in {layout}")
        seeds = sorted(by_seed)
        out[layout] = {"a3c": [by_seed[s] for s in seeds], "a3c+org": [graph[s] for s in seeds]}
    return out


CONTROL_COLUMNS = ("SR", "SPL", LONG)


def _gains(layout: dict, column: str) -> np.ndarray:
    return np.array([g[column] - b[column] for b, g in zip(layout["a3c"], layout["a3c+org"])], float)


def welch(today: np.ndarray, priors: np.ndarray) -> str:
    r = scipy_stats.ttest_ind(priors, today, equal_var=False)
    ci = r.confidence_interval(0.95)
    return interval(priors.mean() - today.mean(), ci.low, ci.high)


def control_table(archives: Archives) -> str:
    """ORG's graph's gain over a3c (both sampled) in each layout, paired by seed, with the
    rule's words; then priors - today, Welch's interval on the two sets of per-seed gains."""
    layouts = control(archives)
    rows = []
    for layout, name in (("today", "today's rooms"), ("priors", "rooms with priors")):
        data = layouts[layout]
        means = [mean_std([o["SR"] for o in data[arm]]) for arm in ("a3c", "a3c+org")]
        judged = [alone(_gains(data, c), c) for c in CONTROL_COLUMNS]
        rows.append([name, *means, *(v.figures() for v in judged), " / ".join(v.words() for v in judged)])
    across = [welch(*(_gains(layouts[x], c) for x in ("today", "priors"))) for c in CONTROL_COLUMNS]
    rows.append(["priors - today (Welch)", "", "", *across, "unpaired: none"])
    header = ["layouts (org setup, sampled)", "a3c SR", "a3c+org SR", "graph's gain, SR", "SPL", "SR on L^g >= 5"]
    return table(header + ["verdict (SR / SPL / SR on L^g >= 5)"], rows, tight=True)


def control_readings(archives: Archives) -> str:
    layouts = control(archives)
    across = [welch(*(_gains(layouts[x], c) for x in ("today", "priors"))) for c in CONTROL_COLUMNS]
    sr = {
        (layout, arm): np.mean([o["SR"] for o in layouts[layout][arm]])
        for layout in layouts
        for arm in ("a3c", "a3c+org")
    }
    return (
        f"- **ORG's graph's gain over a3c, with priors minus today's rooms** (Welch's 95% interval on the two "
        f"layouts' per-seed gains): SR {across[0]}, SPL {across[1]}, SR on L^g >= 5 {across[2]}. The rule's "
        "words need paired seeds; across layouts the seeds share nothing, so these carry none.\n"
        f"- **Each arm's SR in the two layouts** (org setup, sampled actions): a3c {sr['today', 'a3c']:.1f} in "
        f"today's rooms and {sr['priors', 'a3c']:.1f} with priors ({signed(sr['priors', 'a3c'] - sr['today', 'a3c'])}), "
        f"a3c+org {sr['today', 'a3c+org']:.1f} and {sr['priors', 'a3c+org']:.1f} "
        f"({signed(sr['priors', 'a3c+org'] - sr['today', 'a3c+org'])}); unpaired, no verdict.\n"
    )


# ---------------------------------------------------------------------- the probes
def probe(archives: Archives, name: str) -> list[dict]:
    """The per-seed probe of the one arm `experiments.probe` probed in docs/data/`name`."""
    (per_seed,) = archives.probe(name).values()
    return per_seed


FIT = ("r2_over_mean", "category_r2_over_mean", "identity_r2_over_mean", "ridge_r2_over_mean", "offline_r2_over_mean")


def probe_table(archives: Archives, setup: str) -> str:
    """Per seed of the setup's a3c+foresit (`experiments.probe`): the share of sub-goals in the
    first fifth of the episode, then the held-out R^2 of the online f_w, the category mean,
    s_0, ridge on [s_0 : g] and the offline f_w."""
    rows = []
    for r in probe(archives, SETUPS[setup].probe):
        f, sub = r["items"]["fit"], r["items"]["subgoal"]
        rows.append([str(r["seed"]), f"{100 * sub['shares'][0]:.0f}%", *(f"{f[k]:.2f}" for k in FIT)])
    header = ["seed", "t*/T < 0.2", "R^2 online f_w", "category mean", "s_0", "ridge on [s_0 : g]", "offline f_w"]
    return table(header, rows)


def over_category(per_seed: list[dict], key: str) -> list[float]:
    return [r["items"]["fit"][key] - r["items"]["fit"]["category_r2_over_mean"] for r in per_seed]


def above(x) -> str:
    return f"above 0 on {sum(v > 0 for v in x)} of {len(x)} seeds"


def probe_readings(archives: Archives, setup: str) -> str:
    per_seed = probe(archives, SETUPS[setup].probe)
    ridge, offline, online = (
        over_category(per_seed, k) for k in ("ridge_r2_over_mean", "offline_r2_over_mean", "r2_over_mean")
    )
    fit = [r["items"]["fit"] for r in per_seed]
    lines = []
    if setup == "org":
        at_done = [100 * r["items"]["subgoal"]["at_done"] for r in per_seed]
        lines.append(
            f"- **Where the sub-goal lies**: t*/T < 0.2 in {span([100 * r['items']['subgoal']['shares'][0] for r in per_seed], 0, False)}% "
            f"of the successful episodes, the Done step's own state in {span(at_done, 0, False)}%; held-out R^2 of s_0 "
            f"alone {span([f['identity_r2_over_mean'] for f in fit], 2, False)}."
        )
    today = ""
    if setup == "savn":
        today = f" (today's rooms, docs/data/{PROBE_TODAY}: {span(over_category(probe(archives, PROBE_TODAY), 'ridge_r2_over_mean'))}, "
        today += above(over_category(probe(archives, PROBE_TODAY), "ridge_r2_over_mean")) + ")"
    lines.append(
        f"- **Held-out R^2 minus the target category's mean's**, per seed: ridge on [s_0 : g] {span(ridge)}, "
        f"{above(ridge)}{today}; the offline f_w {span(offline)}, {above(offline)}; the online f_w "
        f"{span(online)}, {above(online)} (its R^2 {span([f['r2_over_mean'] for f in fit], 2, False)}, the category "
        f"mean's {span([f['category_r2_over_mean'] for f in fit], 2, False)})."
    )
    conditions = [
        ("shuffled, noise off", "i_tau shuffled across episodes with the noise off"),
        ("untrained f_w", "from an untrained f_w"),
    ]
    if setup == "savn":
        conditions.append(("noise off", "the noise off"))
    else:
        conditions.append(("sampled actions", "sampled actions instead of greedy"))
    lines.append(
        "- **SR against the trained condition**, paired over seeds: "
        + "; ".join(f"{words}, {said(probe_condition(per_seed, c))}" for c, words in conditions)
        + "."
    )
    if setup == "savn":
        shares = [100 * r["items"]["signal"]["signal_share"] for r in per_seed]
        lines.append(f"- **i_tau's signal** is {span(shares, 0, False)}% of its variance at the training-end noise.")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------- the answers
def answers(archives: Archives) -> str:
    """The study's comparisons side by side, savn and org, each in the rule's words."""
    cells: dict[str, list[str]] = {}
    for setup, s in SETUPS.items():
        results = archives.sweep(s.archive, s.arms)
        base, critic, foresit = s.arms
        sr, spl = by_pair(results, pairs_of(s.arms)).values()
        per_seed = probe(archives, s.probe)
        ridge, online = (over_category(per_seed, k) for k in ("ridge_r2_over_mean", "r2_over_mean"))
        for name, v in (
            ("ForeSIT - its critic alone (the imagination, the critic held), SR", sr[critic, foresit]),
            ("ForeSIT - its critic alone, SPL", spl[critic, foresit]),
            ("ForeSIT - its base, SR", sr[base, foresit]),
            ("ForeSIT - its base, SPL", spl[base, foresit]),
            ("the critic alone - its base, SR", sr[base, critic]),
            (
                "i_tau shuffled with the noise off - as trained (the probe), SR",
                probe_condition(per_seed, "shuffled, noise off"),
            ),
        ):
            cells.setdefault(name, []).append(f"{v.figures()}: {v.words()}")
        for name, x in (
            ("ridge on [s_0 : g] - the category mean, held-out R^2", ridge),
            ("the online f_w - the category mean, held-out R^2", online),
        ):
            cells.setdefault(name, []).append(above(x))
    rows = [[name, *both] for name, both in cells.items()]
    return table(["B - A (seeds 0-4; Holm over each setup's three pairs)", "savn", "org"], rows)


# ---------------------------------------------------------------------- the foresight bound there
def foresight(archives: Archives) -> str:
    """What docs/foresight.md measured with `experiments.foresight --priors`: the target's
    gain to the first view's prediction in rooms and houses with priors (savn)."""
    priors, today = archives.json(FORESIGHT_PRIORS), archives.json(FORESIGHT_TODAY)
    rooms, houses = priors["room-savn"]["results"], priors["house-savn"]["results"]
    anchor = rooms["bearing"]["subsets"]["anchor in view"]
    return (
        f"- **Rooms with priors**: the target adds {gain(rooms['bearing'])} points to the bearing's accuracy "
        f"from the first view on held-out rooms (today's rooms: {gain(today['room-savn']['results']['bearing'])}), "
        f"and {gain(rooms['turn'])} to the first turn's.\n"
        f"- **Where the view shows the target's anchor furniture** ({100 * anchor['share']:.0f}% of the starts "
        f"with the target out of view): {gain(anchor)} on the bearing.\n"
        f"- **Houses with priors**, on held-out houses: {gain(houses['turn'])} on the turn, "
        f"{gain(houses['bearing'])} on the bearing.\n"
        "\n(A bootstrap over the test layouts, not the rule's paired seeds: these carry no verdict word.)\n"
    )


BLOCKS = {
    "priors-savn": ("docs/priors.md", lambda a: pairs_table(a, "savn")),
    "priors-savn-readings": ("docs/priors.md", lambda a: readings(a, "savn")),
    "priors-savn-probes": ("docs/priors.md", lambda a: probe_table(a, "savn")),
    "priors-savn-probe-readings": ("docs/priors.md", lambda a: probe_readings(a, "savn")),
    "priors-org": ("docs/priors.md", lambda a: pairs_table(a, "org")),
    "priors-org-readings": ("docs/priors.md", lambda a: readings(a, "org")),
    "priors-org-control": ("docs/priors.md", control_table),
    "priors-org-control-readings": ("docs/priors.md", control_readings),
    "priors-org-probes": ("docs/priors.md", lambda a: probe_table(a, "org")),
    "priors-org-probe-readings": ("docs/priors.md", lambda a: probe_readings(a, "org")),
    "priors-answers": ("docs/priors.md", answers),
    "priors-foresight": ("docs/priors.md", foresight),
}
