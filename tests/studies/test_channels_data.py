"""docs/ceiling.md's channels study (issue 68, docs/plans/ceiling_channels.md) is what its
archives compute: stage 1 (docs/data/channels_stage1.tar.xz, the critic and the two
compasses through `encoder`, rooms with priors at range 4, seeds 0-4, no checkpoints): every
arm's row, each compass's pair with the critic, and the plan's verdict on each (a compass
passes if its SR interval's lower bound is at least the pair's MDE), as the docs word it."""

from pathlib import Path

import numpy as np
import pytest
import study_data
from test_ceiling_data import arm_row

from experiments import compare
from experiments.reporting import report, stats
from experiments import rundir

REPO = Path(__file__).resolve().parents[2]
CRITIC = "a3c+critic@learning_rate=3e-4"
COMPASS = "a3c+compass@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0"
START = "a3c+startcompass@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0"
LABELS = {
    CRITIC: "a3c+critic, rooms with priors, range 4 (channels study)",
    COMPASS: "a3c+compass through `encoder` (privileged), per step",
    START: "a3c+startcompass through `encoder` (privileged), held from the start",
}


def curve_means(per_seed: list[dict]) -> list[float]:
    """The mean over seeds of the validation SR at each of 500, ..., 3000 updates."""
    updates = [[v["update"] for v in r["validation"]] for r in per_seed]
    assert all(u[:6] == [500, 1000, 1500, 2000, 2500, 3000] for u in updates)
    return [float(np.mean([r["validation"][i]["SR"] for r in per_seed])) for i in range(6)]


def curve_row(name: str, per_seed: list[dict]) -> str:
    """The docs' row of the validation table: the means to two decimals (exact: five seeds of
    400 episodes give multiples of 0.05, which one decimal rounds either way)."""
    return f"| {name} | " + " | ".join(f"{m:.2f}" for m in curve_means(per_seed)) + " |"


def passes(pair: dict) -> bool:
    """The plan's rule 1: the SR interval's lower bound at least the pair's MDE of SR."""
    return pair["SR"]["ci_low"] >= pair["robust"]["SR"]["mde"]


def test_stage_1_is_quoted_with_its_verdicts(tmp_path, capsys):
    if not (study_data.DATA / "channels_stage1.tar.xz").exists():
        pytest.skip("channels_stage1.tar.xz: not run yet")
    root = study_data.unpack("channels_stage1.tar.xz", tmp_path, (CRITIC, COMPASS, START))
    for arm in (CRITIC, COMPASS, START):
        config = rundir.read_json(root / "methods" / arm / "run.json")["config"]
        assert config["priors"] is True and config["perception_range"] == 4.0 and config["learning_rate"] == 3e-4
        assert config["num_updates"] == 3000 and config["setup"] == "savn"
        if arm != CRITIC:
            assert config["imagination_input"] == "encoder" and config["sigma2_max"] == 0
    results = rundir.sweep_results(root)
    assert all([r["seed"] for r in results[arm]] == [0, 1, 2, 3, 4] for arm in results)
    out = compare.main(compare.Args(run=root, pairs=(f"{CRITIC}:{COMPASS}", f"{CRITIC}:{START}")))
    capsys.readouterr()
    doc = (REPO / "docs" / "ceiling.md").read_text()
    flat = " ".join(doc.split())
    for arm, label in LABELS.items():
        assert arm_row(results, arm, label) in doc, arm_row(results, arm, label)
    for arm, name in ((COMPASS, "the compass per step"), (START, "the compass at step 0")):
        pair = out["pairs"][f"{arm} - {CRITIC}"]
        mde = f"{pair['robust']['SR']['mde']:.1f}"
        row = (
            f"| {name} - a3c+critic | {study_data.interval(pair['SR'])} | {study_data.interval(pair['SPL'])} | "
            f"{mde} | {'passes' if passes(pair) else 'does not pass'} |"
        )
        assert row in doc, row
    start = out["pairs"][f"{START} - {CRITIC}"]
    assert start["SPL"]["ci_low"] > 0 and start["SR"]["ci_low"] < 0 < start["SR"]["ci_high"]  # the docs' words
    assert (
        "+4.4 [+1.9, +6.8] SPL, a gain that excludes 0" in flat
        and study_data.interval(start["SPL"]) == "+4.4 [+1.9, +6.8]"
    )
    # "The critic reproduces bit for bit": the range-4 study's critic (79dce9c), seed for seed
    earlier = rundir.sweep_results(
        study_data.unpack("ceiling_range4.tar.xz", tmp_path / "range4", (CRITIC, "a3c+oracle@learning_rate=3e-4"))
    )
    for column in ("SR", "SPL"):
        assert list(report.values(results[CRITIC], column)) == list(report.values(earlier[CRITIC], column))
    assert all(r["selected_update"] == 3000 for arm in results for r in results[arm])  # "its last model"
    # the validation table, exact, and the per-step compass's last 500 updates (issue 81: once
    # +3.6 from the rounded table, the critic's row rounded two ways across stages)
    section = doc.split("### Stage 1")[1].split("### Stage 2")[0]
    for arm, name in ((CRITIC, "a3c+critic"), (COMPASS, "a3c+compass, per step"), (START, "a3c+startcompass")):
        assert curve_row(name, results[arm]) in section, curve_row(name, results[arm])
    means = curve_means(results[COMPASS])
    last = f"(+{means[5] - means[4]:.1f} over the last 500: {means[5]:.2f} - {means[4]:.2f})"
    assert last in flat, last


# ---------------------------------------------------------------------- stage 2
ENC = "a3c+oracle@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0"
MLP_CRITIC = "a3c+critic@learning_rate=3e-4,imagination_input=mlp"
MLP = "a3c+oracle@learning_rate=3e-4,imagination_input=mlp,sigma2_max=0"
HEAD = "a3c+oracle@learning_rate=3e-4,sigma2_max=0"
STAGE2 = {
    CRITIC: "a3c+critic (the base of `head` and `encoder`; stage 1's, copied)",
    MLP_CRITIC: "a3c+critic through `mlp` (the base of `mlp`)",
    ENC: "a3c+oracle through `encoder` (privileged), no noise",
    MLP: "a3c+oracle through `mlp` (privileged), no noise",
    HEAD: "a3c+oracle through `head` (privileged), no noise",
}
CEILINGS = ((CRITIC, ENC, "`encoder`"), (MLP_CRITIC, MLP, "`mlp`"), (CRITIC, HEAD, "`head`"))
CHANNELS = (
    (HEAD, ENC, "`encoder` - `head`"),
    (HEAD, MLP, "`mlp` - `head`"),
    (CRITIC, MLP_CRITIC, "the critic: `mlp` - `head`"),
)


def resolved(pair: dict) -> bool:
    """The plan's rule 2: the SR interval above 0 and Holm's p over the goal-view pairs below 0.05."""
    return pair["SR"]["ci_low"] > 0 and pair["robust"]["SR"]["p_holm"] < 0.05


def mean_selected_validation(results: list[dict]) -> float:
    """The plan's rule 3: the mean over seeds of the selected model's validation SR."""
    return sum(next(v["SR"] for v in r["validation"] if v["update"] == r["selected_update"]) for r in results) / len(
        results
    )


def quoted_arms(root: Path, labels: dict) -> tuple[dict, str, str]:
    """A stage's results (every arm over seeds 0-4) and docs/ceiling.md, checked to hold each
    arm's row under its label: (results, the doc, the doc on one line)."""
    results = rundir.sweep_results(root)
    assert all([r["seed"] for r in results[arm]] == [0, 1, 2, 3, 4] for arm in results)
    doc = (REPO / "docs" / "ceiling.md").read_text()
    for arm, label in labels.items():
        assert arm_row(results, arm, label) in doc, arm_row(results, arm, label)
    return results, doc, " ".join(doc.split())


def test_stage_2_is_quoted_with_its_verdicts(tmp_path, capsys):
    if not (study_data.DATA / "channels_stage2.tar.xz").exists():
        pytest.skip("channels_stage2.tar.xz: not run yet")
    root = study_data.unpack(
        "channels_stage2.tar.xz", tmp_path, (CRITIC, ENC, MLP_CRITIC, MLP, HEAD)
    )  # the sweep's order
    for arm in STAGE2:
        config = rundir.read_json(root / "methods" / arm / "run.json")["config"]
        assert config["priors"] is True and config["perception_range"] == 4.0 and config["learning_rate"] == 3e-4
        assert config["num_updates"] == 3000 and config["setup"] == "savn"
        if "oracle" in arm:
            assert config["sigma2_max"] == 0
    assert rundir.read_json(root / "methods" / ENC / "run.json")["config"]["imagination_input"] == "encoder"
    assert {
        rundir.read_json(root / "methods" / a / "run.json")["config"]["imagination_input"] for a in (MLP, MLP_CRITIC)
    } == {"mlp"}
    results, doc, flat = quoted_arms(root, STAGE2)
    out = compare.main(compare.Args(run=root, pairs=tuple(f"{a}:{b}" for a, b, _ in CEILINGS)))
    capsys.readouterr()
    for a, b, name in CEILINGS:
        pair = out["pairs"][f"{b} - {a}"]
        r = pair["robust"]["SR"]
        row = (
            f"| the goal view through {name} - its base | {study_data.interval(pair['SR'])} | "
            f"{study_data.interval(pair['SPL'])} | {r['mde']:.1f} | {r['p_holm']:.3f} | "
            f"{'resolved' if resolved(pair) else 'not resolved'} |"
        )
        assert row in doc, row
    differences = compare.main(compare.Args(run=root, pairs=tuple(f"{a}:{b}" for a, b, _ in CHANNELS)))
    capsys.readouterr()
    for a, b, name in CHANNELS:
        pair = differences["pairs"][f"{b} - {a}"]
        row = (
            f"| {name} | {study_data.interval(pair['SR'])} | {study_data.interval(pair['SPL'])} | "
            f"{pair['robust']['SR']['mde']:.1f} |"
        )
        assert row in doc, row
    best = max((ENC, MLP, HEAD), key=lambda arm: mean_selected_validation(results[arm]))
    assert f"The best channel by the plan's rule 3 is {STAGE2[best].split(' (')[0].split('through ')[1]}" in flat
    # rule 3's figures, and its margin: `head` over `encoder` by 0.1 points (results.md says so)
    chosen = {arm: mean_selected_validation(results[arm]) for arm in (HEAD, ENC, MLP)}
    quote = "the selected models is {:.2f} through `head`, {:.2f} through `encoder` and {:.2f} through `mlp`".format(
        *chosen.values()
    )
    assert quote in flat, quote
    lead = chosen[HEAD] - chosen[ENC]
    assert f"`head` leads `encoder` by {lead:.1f} points" in flat
    results_md = " ".join((REPO / "docs" / "results.md").read_text().split())
    assert (
        f"rule 3 chose `head` as the best channel by {lead:.1f} points of mean validation SR over `encoder` "
        f"({chosen[HEAD]:.2f} against {chosen[ENC]:.2f}; `mlp` {chosen[MLP]:.2f};"
    ) in results_md
    section = doc.split("### Stage 2")[1].split("### Stage 3")[0]
    for arm, label in STAGE2.items():
        name = label.split(" (")[0]
        assert curve_row(name, results[arm]) in section, curve_row(name, results[arm])
    # Stage 1's critic, copied by --reuse: the same numbers
    first = rundir.sweep_results(
        study_data.unpack("channels_stage1.tar.xz", tmp_path / "stage1", (CRITIC, COMPASS, START))
    )
    assert list(report.values(first[CRITIC], "SR")) == list(report.values(results[CRITIC], "SR"))
    # the goal view against its timing-matched control, the start compass, paired directly over
    # the same seeds (stage 1's arm, this stage's arms): ceiling.md and results.md quote them
    start = first[START]
    direct = {}
    for arm in (ENC, MLP, HEAD):
        assert [r["seed"] for r in results[arm]] == [r["seed"] for r in start]
        direct[arm] = {
            m: study_data.interval(stats.paired(report.values(start, m), report.values(results[arm], m)))
            for m in ("SR", "SPL")
        }
    assert stats.paired(report.values(start, "SR"), report.values(results[MLP], "SR"))["ci_high"] < 0
    quote = (
        f"is {direct[ENC]['SR']} SR through `encoder`, {direct[MLP]['SR']} through `mlp` and "
        f"{direct[HEAD]['SR']} through `head`"
    )
    assert quote in flat, quote
    assert f"(SPL through `head`: {direct[HEAD]['SPL']})" in flat
    assert quote.replace("is ", "the goal view is ", 1) in results_md, quote
    # "The head arm reproduces bit for bit": the range-4 study's noise-off oracle (79dce9c)
    earlier = rundir.sweep_results(
        study_data.unpack(
            "ceiling_range4_noiseoff.tar.xz", tmp_path / "noiseoff", (CRITIC, "a3c+oracle@learning_rate=3e-4", HEAD)
        )
    )
    for column in ("SR", "SPL"):
        assert list(report.values(results[HEAD], column)) == list(report.values(earlier[HEAD], column))


# ---------------------------------------------------------------------- stage 3
STAGE3 = {
    CRITIC: "a3c+critic, 9000 updates",
    HEAD: "a3c+oracle through `head` (privileged), no noise, 9000 updates",
}


def head_ceiling(root: Path, doc: str, where: str, capsys) -> dict:
    """The pair `head` - critic of a stage's sweep, checked to be docs/ceiling.md's row for
    `where`: SR, SPL, the validation area, the MDE, Holm's p and the plan's rule 2."""
    out = compare.main(compare.Args(run=root, pairs=(f"{CRITIC}:{HEAD}",)))
    capsys.readouterr()
    pair = out["pairs"][f"{HEAD} - {CRITIC}"]
    row = (
        f"| the goal view through `head` - its base, {where} | {study_data.interval(pair['SR'])} | "
        f"{study_data.interval(pair['SPL'])} | {study_data.interval(pair[report.VALIDATION_AREA])} | "
        f"{pair['robust']['SR']['mde']:.1f} | {pair['robust']['SR']['p_holm']:.3f} | "
        f"{'resolved' if resolved(pair) else 'not resolved'} |"
    )
    assert row in doc, row
    return pair


def test_stage_3_is_quoted_with_its_verdicts(tmp_path, capsys):
    """Stage 3, the budget branch (docs/data/channels_stage3.tar.xz): the critic and the best
    channel, `head`, extended from stage 2's 3000 updates to 9000; each arm's row, the goal
    view's ceiling at 9000 (the selected model's test SR and SPL, and the area under the
    validation curve) with the plan's rule 2, and each arm's gain from the longer budget
    against its own 3000-update results (kept beside as results_3000_updates.json)."""
    if not (study_data.DATA / "channels_stage3.tar.xz").exists():
        pytest.skip("channels_stage3.tar.xz: not run yet")
    from experiments.reporting import stats

    root = study_data.unpack("channels_stage3.tar.xz", tmp_path, (CRITIC, HEAD))
    for arm in STAGE3:
        config = rundir.read_json(rundir.arm_folder(root, arm) / "run.json")["config"]
        assert config["priors"] is True and config["perception_range"] == 4.0 and config["learning_rate"] == 3e-4
        assert config["num_updates"] == 9000 and config["setup"] == "savn"
    assert rundir.read_json(rundir.arm_folder(root, HEAD) / "run.json")["config"]["sigma2_max"] == 0
    results, doc, flat = quoted_arms(root, STAGE3)
    pair = head_ceiling(root, doc, "9000 updates", capsys)
    # the budget: each arm at 9000 against its own 3000-update results, seed by seed
    stage2 = rundir.sweep_results(
        study_data.unpack("channels_stage2.tar.xz", tmp_path / "stage2", (CRITIC, ENC, MLP_CRITIC, MLP, HEAD))
    )
    for arm, label in STAGE3.items():
        before = rundir.read_json(rundir.arm_folder(root, arm) / rundir.kept_results(3000), ("results",))["results"]
        for column in ("SR", "SPL"):  # the runs were copied from stage 2, then extended
            assert list(report.values(before, column)) == list(report.values(stage2[arm], column))
        gains = {c: stats.paired(report.values(before, c), report.values(results[arm], c)) for c in ("SR", "SPL")}
        row = (
            f"| {label.split(',')[0]}: 9000 - 3000 updates | {study_data.interval(gains['SR'])} | "
            f"{study_data.interval(gains['SPL'])} |"
        )
        assert row in doc, row
    # the README's and results.md's sentences quote the ceiling and the critic's budget gain
    critic_before = rundir.read_json(rundir.arm_folder(root, CRITIC) / rundir.kept_results(3000), ("results",))
    critic_gain = stats.paired(report.values(critic_before["results"], "SR"), report.values(results[CRITIC], "SR"))
    results_md = " ".join((REPO / "docs" / "results.md").read_text().split())
    assert (
        f"{study_data.interval(pair['SR'])} SR (MDE {pair['robust']['SR']['mde']:.1f}), while the budget itself is "
        f"worth {study_data.interval(critic_gain)} SR to the critic"
    ) in results_md
    selected = {arm: [r["selected_update"] for r in results[arm]] for arm in results}
    for arm, label in STAGE3.items():
        line = f"{label.split(',')[0]} selected updates {', '.join(map(str, selected[arm]))}"
        assert line in flat, line


# ---------------------------------------------------------------------- stage 4
STAGE4 = {
    CRITIC: "a3c+critic, today's rooms (channels study)",
    HEAD: "a3c+oracle through `head` (privileged), no noise, today's rooms",
}


def first_difference(a: list, b: list) -> int | None:
    """The first update at which two training curves differ (None: they never do)."""
    return next((i for i, (x, y) in enumerate(zip(a, b, strict=True)) if x != y), None)


def test_stage_4_is_quoted_with_its_verdicts(tmp_path, capsys):
    """Stage 4, today's rooms (docs/data/channels_rooms.tar.xz): the critic and the best
    channel, `head`, at quick's budget without priors or range; each arm's row, the goal
    view's ceiling (test SR and SPL, the area under the validation curve) with the plan's
    rule 2, the validation curve's rows, and the claim that neither arm repeats its 2498418
    run (docs/data/ceiling_savn_epyc.tar.xz): the training curves agree for the first 74 to
    325 updates, then part."""
    if not (study_data.DATA / "channels_rooms.tar.xz").exists():
        pytest.skip("channels_rooms.tar.xz: not run yet")
    root = study_data.unpack("channels_rooms.tar.xz", tmp_path, (CRITIC, HEAD))
    for arm in STAGE4:
        run = rundir.read_json(rundir.arm_folder(root, arm) / rundir.RUN_FILE)
        assert [c[:7] for c in run["commits"]] == ["431bbf4"]  # the worktree's commit
        config = run["config"]
        assert config["priors"] is False and config.get("perception_range") is None
        assert config["num_updates"] == 3000 and config["setup"] == "savn" and config["learning_rate"] == 3e-4
        assert config["room_types"] == [] and config["layout"] == "room"
    assert rundir.read_json(rundir.arm_folder(root, HEAD) / "run.json")["config"]["sigma2_max"] == 0
    results, doc, flat = quoted_arms(root, STAGE4)
    pair = head_ceiling(root, doc, "today's rooms", capsys)
    # the words: SR cannot be told from 0; SPL and the validation area exclude it
    assert pair["SR"]["ci_low"] < 0 < pair["SR"]["ci_high"] and not resolved(pair)
    assert pair["SPL"]["ci_low"] > 0 and pair[report.VALIDATION_AREA]["ci_low"] > 0
    section = doc.split("### Stage 4")[1]
    for arm, label in STAGE4.items():
        curve = {}
        for r in results[arm]:
            for v in r["validation"]:
                curve.setdefault(v["update"], []).append(v["SR"])
        name = label.split(",")[0].split(" (privileged)")[0]
        line = f"| {name} | " + " | ".join(f"{sum(x) / len(x):.1f}" for _, x in sorted(curve.items())) + " |"
        assert line in section, line
    assert [r["selected_update"] for r in results[HEAD]] == [3000] * 5
    assert sorted(r["selected_update"] for r in results[CRITIC]) == [2500, 3000, 3000, 3000, 3000]
    # neither arm repeats its 2498418 run: the curves agree at first, then part
    earlier = study_data.unpack(
        "ceiling_savn_epyc.tar.xz", tmp_path / "epyc", (CRITIC, "a3c+oracle@learning_rate=3e-4", HEAD)
    )
    firsts = []
    for arm in STAGE4:
        now = rundir.read_json(rundir.arm_folder(root, arm) / rundir.RESULTS_FILE)
        before = rundir.read_json(rundir.arm_folder(earlier, arm) / rundir.RESULTS_FILE)
        # the same platform, so the parting is the start's, not the machine's
        assert [r["numerics"] for r in now["results"]] == [r["numerics"] for r in before["results"]]
        firsts += [first_difference(a, b) for a, b in zip(now["curves"], before["curves"], strict=True)]
    assert None not in firsts, "a curve repeats its 2498418 run to the end: the docs say they part"
    assert f"for its first {min(firsts)} to {max(firsts)} updates, then the two part" in flat
    # the earlier run of the pair, quoted beside this one
    old = compare.main(compare.Args(run=earlier, pairs=(f"{CRITIC}:{HEAD}",)))["pairs"][f"{HEAD} - {CRITIC}"]
    capsys.readouterr()
    quoted = (
        f"gave {study_data.interval(old['SR'])} SR, {study_data.interval(old['SPL'])} SPL and "
        f"{study_data.interval(old[report.VALIDATION_AREA])} validation SR area: the area's interval lies above 0 "
        "in both runs, SPL's in this one only"
    )
    assert quoted in flat, quoted
    assert old[report.VALIDATION_AREA]["ci_low"] > 0 and old["SPL"]["ci_low"] < 0
    # the README's and results.md's sentences
    sr, mde = study_data.interval(pair["SR"]), f"{pair['robust']['SR']['mde']:.1f}"
    # the ceiling study's summary names this run's upper end beside its own (issue 81: +4.9 alone)
    assert f"reaches {study_data.signed(pair['SR']['ci_high'])} ({sr} SR)" in flat
    results_md = " ".join((REPO / "docs" / "results.md").read_text().split())
    assert (
        f"(the plan's stage 4), through `head`: {sr} SR (MDE {mde}), not resolved; in SPL this run's interval "
        f"lies above 0, {study_data.interval(pair['SPL'])}, and an earlier run of the same pair gave "
        f"{study_data.interval(old['SPL'])}"
    ) in results_md
