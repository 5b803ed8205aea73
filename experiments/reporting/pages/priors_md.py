"""docs/priors.md's generated blocks: the paper's question in rooms with priors (savn and org,
seeds 0-4), ORG's control, the probes, the study's answers, and what the foresight tool
measured there.

Read from docs/data's priors_savn.tar.xz, priors_org.tar.xz, priors_org_control.tar.xz,
priors_probe_{savn,org}.json, foresight_{today,priors}.json, and, for the same pairs in
today's rooms, fair_tune.tar.xz, fair_tune_org.tar.xz and fair_probe_lr3e-4.json. Every
verdict word is `verdicts.verdict`'s: the three pairs of a setup are one family on each
metric (Holm, as the tables' p column says); everything else is judged alone.

`archive_json` and `data_json` read what `registry.Archives` does not (a JSON member of an
archive other than an arm's results, a JSON file of docs/data), once per `Archives`; with
`family` they could move to the registry (docs/houses.md's page uses them too).
"""

from __future__ import annotations

import json
import tarfile
import weakref
from typing import NamedTuple

import numpy as np
from scipy import stats as scipy_stats

from experiments.reporting import report, stats
from experiments.reporting.registry import PAPER_MARGIN, Archives
from experiments.reporting.verdicts import Verdict, verdict

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


# ---------------------------------------------------------------------- reading
_JSON: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _cache(archives: Archives) -> dict:
    return _JSON.setdefault(archives, {})


def archive_json(archives: Archives, archive: str, member: str):
    """The JSON member `member` (its path inside the archive) of docs/data/`archive`
    (`archives.data`), read in place; an archive's members are read once per `archives`
    (every JSON member but the arms' progress files)."""
    cache = _cache(archives)
    if archive not in cache:
        with tarfile.open(archives.data / archive) as tar:
            cache[archive] = {
                m.name: json.load(tar.extractfile(m))
                for m in tar.getmembers()
                if m.isfile() and m.name.endswith(".json") and not m.name.endswith("/progress.json")
            }
    members = cache[archive]
    if member not in members:
        raise KeyError(f"{archive} holds no {member!r}")
    return members[member]


def data_json(archives: Archives, name: str):
    """docs/data/`name` (`archives.data`), a JSON file, read once per `archives`."""
    cache = _cache(archives)
    if name not in cache:
        cache[name] = json.loads((archives.data / name).read_text())
    return cache[name]


def study(archives: Archives, archive: str, arms) -> dict[str, list[dict]]:
    return {arm: archives.results(archive, arm) for arm in arms}


# ---------------------------------------------------------------------- judging
def signed(x: float) -> str:
    return f"{x:+.1f}".replace("+-", "-")


def interval(diff: float, low: float, high: float) -> str:
    return f"{signed(diff)} [{signed(low)}, {signed(high)}]"


def differences(results: dict, a: str, b: str, metric: str) -> np.ndarray:
    ra, rb = results[a], results[b]
    if [r["seed"] for r in ra] != [r["seed"] for r in rb]:
        raise ValueError(f"{a} and {b} were not run on the same seeds")
    return report.values(rb, metric) - report.values(ra, metric)


def family(results: dict, pairs, metric: str, margin: float = PAPER_MARGIN) -> list[Verdict]:
    """The rule's verdicts on B - A of each (A, B) of `pairs`, one family: Holm over the
    pairs' paired p-values (as `experiments.compare` adjusts them)."""
    diffs = [differences(results, a, b, metric) for a, b in pairs]
    adjusted = stats.holm([stats.paired(np.zeros_like(d), d)["p"] for d in diffs])
    return [verdict(d, metric, margin, p_adjusted=float(p)) for d, p in zip(diffs, adjusted)]


def alone(diffs, metric: str, margin: float = PAPER_MARGIN) -> Verdict:
    return verdict(diffs, metric, margin)


def said(v: Verdict, metric: str = "", holm: bool = False) -> str:
    """ "SR +2.7 [-2.1, +7.5]: cannot tell (MDE 6.4)", with Holm's p where a family was judged."""
    return f"{metric or v.metric} {v.figures()}: {v.words()}" + (f", Holm p {v.p:.3f}" if holm else "")


def mean_std(x) -> str:
    s = stats.summary(x)
    return f"{s['mean']:.1f} ± {s['std']:.1f}"


def span(x, digits: int = 2, signs: bool = True) -> str:
    """ "+0.19 to +0.24": the smallest and the largest of `x`."""
    fmt = f"{{:{'+' if signs else ''}.{digits}f}}"
    return f"{fmt.format(min(x))} to {fmt.format(max(x))}"


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
    results = study(archives, s.archive, s.arms)
    pairs = pairs_of(s.arms)
    _, out = report.paired_report(results, pairs, ["SR", "SPL"])
    words = {m: family(results, pairs, m) for m in ("SR", "SPL")}
    rows = []
    for i, (a, b) in enumerate(pairs):
        r = out[f"{b} - {a}"]["robust"]["SR"]
        poi = r["probability_of_improvement"]
        sr, spl = words["SR"][i], words["SPL"][i]
        rows.append(
            f"| {b} - {a} | {mean_std(report.values(results[b], 'SR'))} | {sr.figures()} | {spl.figures()} | "
            f"{poi[0]:.2f} [{poi[1]:.2f}, {poi[2]:.2f}] | {r['p_holm']:.3f} | {r['mde']:.1f} | "
            f"{sr.words()} | {spl.words()} |"
        )
    header = (
        "| B - A (seeds 0-4) | B's SR | SR [95% CI] | SPL [95% CI] | P(B > A) | p (Holm, 3 pairs) | MDE | "
        "verdict, SR | verdict, SPL |\n|---|---|---|---|---|---|---|---|---|\n"
    )
    base = results[s.arms[0]]
    note = f"{s.arms[0]}: {mean_std(report.values(base, 'SR'))} SR"
    if setup == "org":
        note += f", {np.mean(report.values(base, 'SPL')):.1f} SPL"
    return (
        header
        + "\n".join(rows)
        + f"\n\n({note}. P(B > A), p and the MDE are SR's; each verdict is the rule's on its metric, Holm over "
        "the three pairs of that metric.)\n"
    )


def today_arm(arm: str) -> str:
    return arm if "@" in arm else arm + QUICK_RATE


def readings(archives: Archives, setup: str) -> str:
    """The setup's pairs in words: the rule's verdicts (Holm over the three pairs), the long
    paths (L^g >= 5), the same pairs in today's rooms (each arm at the rate today's tune
    chose), and each arm's SR here and there."""
    s = SETUPS[setup]
    results = study(archives, s.archive, s.arms)
    base, critic, foresit = s.arms
    pairs = pairs_of(s.arms)
    sr, spl = (dict(zip(pairs, family(results, pairs, m))) for m in ("SR", "SPL"))
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
        f"{arm} {np.mean(report.values(results[arm], 'SR')):.1f} here, "
        f"{np.mean(report.values(today_results[arm], 'SR')):.1f} there"
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
    sampled = archive_json(archives, CONTROL, "priors_org_control/org_sampled.json")
    out = {}
    for layout, folder in (("today", "org_control"), ("priors", "org_control_priors")):
        base = archive_json(archives, CONTROL, f"priors_org_control/{folder}/methods/a3c/results.json")["results"]
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
        means = " | ".join(mean_std([o["SR"] for o in data[arm]]) for arm in ("a3c", "a3c+org"))
        judged = [alone(_gains(data, c), c) for c in CONTROL_COLUMNS]
        rows.append(
            f"| {name} | {means} | "
            + " | ".join(v.figures() for v in judged)
            + " | "
            + " / ".join(v.words() for v in judged)
            + " |"
        )
    across = [welch(*(_gains(layouts[x], c) for x in ("today", "priors"))) for c in CONTROL_COLUMNS]
    rows.append("| priors - today (Welch) | | | " + " | ".join(across) + " | unpaired: none |")
    header = (
        "| layouts (org setup, sampled) | a3c SR | a3c+org SR | graph's gain, SR | SPL | SR on L^g >= 5 | "
        "verdict (SR / SPL / SR on L^g >= 5) |\n|---|---|---|---|---|---|---|\n"
    )
    return header + "\n".join(rows) + "\n"


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
    (per_seed,) = data_json(archives, name)["methods"].values()
    return per_seed


FIT = ("r2_over_mean", "category_r2_over_mean", "identity_r2_over_mean", "ridge_r2_over_mean", "offline_r2_over_mean")


def probe_table(archives: Archives, setup: str) -> str:
    """Per seed of the setup's a3c+foresit (`experiments.probe`): the share of sub-goals in the
    first fifth of the episode, then the held-out R^2 of the online f_w, the category mean,
    s_0, ridge on [s_0 : g] and the offline f_w."""
    rows = []
    for r in probe(archives, SETUPS[setup].probe):
        f, sub = r["items"]["fit"], r["items"]["subgoal"]
        cells = [f"{100 * sub['shares'][0]:.0f}%"] + [f"{f[k]:.2f}" for k in FIT]
        rows.append(f"| {r['seed']} | " + " | ".join(cells) + " |")
    header = (
        "| seed | t*/T < 0.2 | R^2 online f_w | category mean | s_0 | ridge on [s_0 : g] | offline f_w |\n"
        "|---|---|---|---|---|---|---|\n"
    )
    return header + "\n".join(rows) + "\n"


def over_category(per_seed: list[dict], key: str) -> list[float]:
    return [r["items"]["fit"][key] - r["items"]["fit"]["category_r2_over_mean"] for r in per_seed]


def above(x) -> str:
    return f"above 0 on {sum(v > 0 for v in x)} of {len(x)} seeds"


def condition(per_seed: list[dict], name: str) -> Verdict:
    """SR with i_tau's `name` condition minus SR as trained, paired over seeds."""
    trained = np.array([r["sr"]["trained"] for r in per_seed])
    return alone(np.array([r["sr"][name] for r in per_seed]) - trained, "SR")


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
        + "; ".join(f"{words}, {said(condition(per_seed, c))}" for c, words in conditions)
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
        results = study(archives, s.archive, s.arms)
        base, critic, foresit = s.arms
        pairs = pairs_of(s.arms)
        sr, spl = (dict(zip(pairs, family(results, pairs, m))) for m in ("SR", "SPL"))
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
                condition(per_seed, "shuffled, noise off"),
            ),
        ):
            cells.setdefault(name, []).append(f"{v.figures()}: {v.words()}")
        for name, x in (
            ("ridge on [s_0 : g] - the category mean, held-out R^2", ridge),
            ("the online f_w - the category mean, held-out R^2", online),
        ):
            cells.setdefault(name, []).append(above(x))
    rows = [f"| {name} | {' | '.join(values)} |" for name, values in cells.items()]
    return (
        "| B - A (seeds 0-4; Holm over each setup's three pairs) | savn | org |\n|---|---|---|\n"
        + "\n".join(rows)
        + "\n"
    )


# ---------------------------------------------------------------------- the foresight bound there
def gain(r: dict) -> str:
    lo, hi = r["gain_ci"]
    return interval(100 * r["gain"], 100 * lo, 100 * hi)


def foresight(archives: Archives) -> str:
    """What docs/foresight.md measured with `experiments.foresight --priors`: the target's
    gain to the first view's prediction in rooms and houses with priors (savn)."""
    priors, today = data_json(archives, FORESIGHT_PRIORS), data_json(archives, FORESIGHT_TODAY)
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
