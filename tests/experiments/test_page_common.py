"""What the page modules share (experiments/reporting/pages/common.py: the formats, the Holm
families, a probe's conditions) and how `registry.Archives` reads an archive in place (its arms'
results, another results file they keep, any JSON member, docs/data's JSON files), on
hand-computed values and a hand-made archive."""

import json
import math
import tarfile

import numpy as np
import pytest

from experiments.reporting import registry
from experiments.reporting.pages import common
from experiments.reporting.verdicts import verdict


def p_of_three(d) -> float:
    """The two-sided paired t-test's p over three seeds, by hand: with 2 degrees of freedom the
    t distribution's CDF is 1/2 + t / (2 sqrt(2 + t^2)), so p = 1 - |t| / sqrt(2 + t^2)."""
    d = np.asarray(d, float)
    t = d.mean() / (d.std(ddof=1) / math.sqrt(3))
    return 1 - abs(t) / math.sqrt(2 + t * t)


# ---------------------------------------------------------------------- formats
def test_signed_intervals_and_figures():
    assert [common.signed(x) for x in (2.14, -0.04, 0.0)] == ["+2.1", "-0.0", "+0.0"]
    assert common.signed(0.1234, 3) == "+0.123"
    assert common.interval(1.4, -2.04, 4.66) == "+1.4 [-2.0, +4.7]"
    assert common.interval(-0.123, -0.2, 0.051, 2) == "-0.12 [-0.20, +0.05]"
    assert common.figures({"diff": 1.0, "ci_low": -0.5, "ci_high": 2.5}) == "+1.0 [-0.5, +2.5]"
    # differences 1, 2, 3: mean 2, std 1, t(0.975, 2) = 4.3027, half-width 4.3027 / sqrt(3) = 2.484
    assert common.paired_figures([0, 0, 0], [1, 2, 3]) == "+2.0 [-0.5, +4.5]"
    assert common.paired_figures([0, 0, 0], [1, 2, 3], 2) == "+2.00 [-0.48, +4.48]"


def test_bootstraps_gains_and_spreads():
    assert common.bootstrap((62.71, 55.83, 67.29)) == "62.7 [55.8, 67.3]"
    assert common.bootstrap((0.5, 0.25, 0.751), 2) == "0.50 [0.25, 0.75]"
    assert common.gain({"gain": 0.031, "gain_ci": [0.021, 0.041]}) == "+3.1 [+2.1, +4.1]"
    assert common.gain({"gain": -0.004, "gain_ci": [-0.012, 0.006]}) == "-0.4 [-1.2, +0.6]"
    assert common.mean_std([1, 2, 3]) == "2.0 ± 1.0"
    assert common.mean_std([1, 2, 3, float("nan")]) == "2.0 ± 1.0"  # an empty bucket's NaN is left out
    assert common.mean_std([58.0, 62.0]) == "60.0 ± 2.8"  # sample std: sqrt(8)
    assert common.seed_by_seed([61.23, 58, 64.06]) == "61.2 / 58.0 / 64.1"
    assert common.seed_by_seed([0.5, 1], 2) == "0.50 / 1.00"
    assert common.span([0.2, 0.19, 0.24]) == "+0.19 to +0.24"
    assert common.span([-0.0123, 0.004], 3) == "-0.012 to +0.004"
    assert common.span([19.4, 24.2], 0, signs=False) == "19 to 24"


def test_a_table_and_its_empty_cells():
    assert common.table(["a", "b"], [["1", "2"], ["3", ""]]) == "| a | b |\n|---|---|\n| 1 | 2 |\n| 3 |  |\n"
    assert common.table(["a", ""], [["", "x"]], tight=True) == "| a | |\n|---|---|\n| | x |\n"


def test_a_verdict_in_words():
    v = verdict([1, 2, 3], "SR", 3.8)  # 95% [-0.48, +4.48]; 90% [+0.31, +3.69], inside ±3.8
    assert common.cells(v) == ["+2.0 [-0.5, +4.5]", "level within ±3.8"]
    assert common.said(v) == "SR +2.0 [-0.5, +4.5]: level within ±3.8"
    assert common.said(v, "SR on L^g >= 5", holm=True) == (
        f"SR on L^g >= 5 +2.0 [-0.5, +4.5]: level within ±3.8, Holm p {p_of_three([1, 2, 3]):.3f}"
    )


# ---------------------------------------------------------------------- Holm families
def test_a_family_is_judged_with_holms_adjusted_p():
    """p 0.0742 ([1, 2, 3]) and 0.1885 ([1, 2, 6]) alone; Holm over the two: the smaller times
    two (0.1484), the larger times one, kept at least the one before (0.1885)."""
    small, large = [1.0, 2.0, 3.0], [1.0, 2.0, 6.0]
    raw = [p_of_three(small), p_of_three(large)]
    assert raw == pytest.approx([0.07418, 0.18850], abs=1e-5)
    alone = common.verdicts_of([small, large], "SR", holm=False)
    family = common.verdicts_of([small, large], "SR")
    assert [v.p for v in alone] == pytest.approx(raw)
    assert [v.p for v in family] == pytest.approx([2 * raw[0], raw[1]])
    assert [v.figures() for v in alone] == [v.figures() for v in family]
    assert [v.p for v in common.verdicts_of([small], "SR")] == pytest.approx(raw[:1])  # one pair: alone
    assert common.alone(small, "SR").p == pytest.approx(raw[0])


def seed(s: int, sr: float, **more) -> dict:
    return {"seed": s, "selected": {"overall": {"SR": sr, "SPL": sr / 2}}, **more}


def test_a_family_of_arms_pairs_them_seed_by_seed():
    results = {
        "a": [seed(s, x) for s, x in enumerate((50.0, 52.0, 54.0))],
        "b": [seed(s, x) for s, x in enumerate((51.0, 54.0, 57.0))],  # b - a: 1, 2, 3
        "c": [seed(s, x) for s, x in enumerate((51.0, 54.0, 60.0))],  # c - a: 1, 2, 6
    }
    assert list(common.differences(results, "a", "c", "SPL")) == [0.5, 1.0, 3.0]
    judged = common.by_pair(results, [("a", "b"), ("a", "c")])
    assert [v.p for v in judged["SR"].values()] == pytest.approx([2 * p_of_three([1, 2, 3]), p_of_three([1, 2, 6])])
    assert judged["SPL"]["a", "b"].figures() == "+1.0 [-0.2, +2.2]"  # half the SR differences
    results["d"] = [seed(s, 50.0) for s in (0, 1, 5)]
    with pytest.raises(ValueError, match="same seeds"):
        common.family(results, [("a", "d")], "SR")


def test_a_probes_condition_against_the_policy_as_trained():
    per_seed = [{"sr": {"trained": t, "shuffled": t + d}} for t, d in ((50.0, 1.0), (52.0, 2.0), (54.0, 3.0))]
    v = common.probe_condition(per_seed, "shuffled")
    assert (v.figures(), v.word, v.n) == ("+2.0 [-0.5, +4.5]", "level", 3)


# ---------------------------------------------------------------------- the archives, read in place
@pytest.fixture
def archives(tmp_path):
    """docs/data made by hand: an extended sweep of two arms (its results at 9000 updates and
    those kept at 3000), a report beside them, and a probe's JSON file."""
    sweep = tmp_path / "sweep"
    arms = {"base": (60.0, 62.0, 58.0), "b": (61.0, 65.0, 58.5)}  # b - base: 1, 3, 0.5
    validation = {"base": 40.0, "b": 30.0}  # each seed's selected model's validation SR: base is chosen
    for arm, srs in arms.items():
        folder = sweep / "methods" / arm
        folder.mkdir(parents=True)
        chose = {"selected_update": 9000, "validation": [{"update": 9000, "SR": validation[arm]}]}
        results = [seed(s, x, **chose) for s, x in enumerate(srs)]
        (folder / "results.json").write_text(json.dumps({"results": results}))
        kept = [seed(s, x - 10) for s, x in enumerate(srs)]
        (folder / "results_3000_updates.json").write_text(json.dumps({"results": kept}))
        (folder / "progress.json").write_text("not read")
    (sweep / "report.json").write_text(json.dumps({"seeds": 3}))
    data = tmp_path / "data"
    data.mkdir()
    with tarfile.open(data / "hand.tar.xz", "w:xz") as tar:
        tar.add(sweep, arcname="sweep")
    (data / "probe.json").write_text(json.dumps({"methods": {"b": [{"seed": 0, "sr": {"trained": 1.0}}]}}))
    return registry.Archives(data)


def test_archives_read_results_members_and_files(archives):
    assert sorted(archives.arms("hand.tar.xz")) == ["b", "base"]
    assert [r["selected"]["overall"]["SR"] for r in archives.results("hand.tar.xz", "b")] == [61.0, 65.0, 58.5]
    kept = archives.results("hand.tar.xz", "b", "results_3000_updates.json")
    assert [r["selected"]["overall"]["SR"] for r in kept] == [51.0, 55.0, 48.5]
    assert archives.member("hand.tar.xz", "sweep/report.json") == {"seeds": 3}
    assert set(archives.sweep("hand.tar.xz")) == {"b", "base"}
    assert archives.results("hand.tar.xz", "b") is archives.sweep("hand.tar.xz", ["b"])["b"]  # read once
    assert archives.probe("probe.json") == {"b": [{"seed": 0, "sr": {"trained": 1.0}}]}
    with pytest.raises(KeyError, match="holds no arm 'c'"):
        archives.results("hand.tar.xz", "c")
    with pytest.raises(KeyError, match="holds no 'sweep/methods/b/progress.json'"):
        archives.member("hand.tar.xz", "sweep/methods/b/progress.json")  # progress files are not read


def test_pairs_of_refs_are_judged_once(archives):
    pair = registry.Pair(registry.Ref("hand.tar.xz", "base"), registry.Ref("hand.tar.xz", "b"))
    assert pair.name(archives) == "b - base"
    assert list(pair.differences(archives, "SR")) == [1.0, 3.0, 0.5]
    budget = registry.Pair(
        registry.Ref("hand.tar.xz", "b", "results_3000_updates.json"), registry.Ref("hand.tar.xz", "b")
    )
    assert list(budget.differences(archives, "SR")) == [10.0, 10.0, 10.0]
    v = common.judged(archives, [pair], "SR")
    assert v[0].figures() == "+1.5 [-1.8, +4.8]"  # mean 1.5, std 1.32, t(0.975, 2) 4.303: half 3.29
    assert common.judged(archives, [pair], "SR") is v  # judged once per Archives
    chosen, other = (registry.Ref("hand.tar.xz", c(("b", "base"))) for c in (registry.Chosen, registry.Unchosen))
    assert (chosen.name(archives), other.name(archives)) == ("base", "b")
    assert list(registry.Pair(other, chosen).differences(archives, registry.VALIDATION)) == [10.0, 10.0, 10.0]
