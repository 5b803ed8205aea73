"""experiments.compare against a hand computation (numpy and scipy's paired t-test) on a
sweep folder written by hand."""

import json

import numpy as np
import pytest
from scipy import integrate
from scipy import stats as sp

from experiments import compare
from experiments.reporting import stats
from experiments import errors

SEEDS = (3, 4, 5, 6)


def write_sweep(root, rng, methods=("a", "b", "c", "d"), seeds=SEEDS):
    """A sweep folder as experiments.sweep writes it, with random numbers; returns them."""
    truth = {}
    for method in methods:
        per_seed = []
        for seed in seeds:
            overall = {"SR": rng.uniform(30, 80), "SPL": rng.uniform(10, 40), "SR>=5": rng.uniform(20, 60)}
            per_seed.append(
                {
                    "seed": seed,
                    "selected": {"overall": overall},
                    "training_success_rate": rng.uniform(0, 1, 300).tolist(),
                    "diagnostics": {"losses/entropy": rng.uniform(0.2, 1, 6).tolist()},
                    "counts": {"frames/useful": 1.5e6 + seed, "charts/episodes": 1000 + seed},
                    "validation": [{"update": u, "SR": rng.uniform(0, 90)} for u in (1000, 500, 1500, 2500)],
                }
            )
        truth[method] = per_seed
        folder = root / "methods" / method
        folder.mkdir(parents=True)
        (folder / "results.json").write_text(json.dumps({"results": per_seed}))
    return truth


def hand_paired(x, y):
    d = np.asarray(y) - np.asarray(x)
    half = sp.t.ppf(0.975, len(d) - 1) * d.std(ddof=1) / np.sqrt(len(d))
    return d.mean(), d.mean() - half, d.mean() + half, sp.ttest_rel(y, x).pvalue


def test_pairs_and_difference_of_differences_match_a_hand_computation(tmp_path, capsys):
    truth = write_sweep(tmp_path, np.random.default_rng(0))
    out = compare.main(compare.Args(run=tmp_path, pairs=("a:b",), did=("a:b:c:d",), last=100))
    printed = capsys.readouterr().out

    def col(method, name):
        if name == "training SR":
            return [100 * np.mean(r["training_success_rate"][-100:]) for r in truth[method]]
        if name == "losses/entropy":
            return [r["diagnostics"][name][-1] for r in truth[method]]
        if name == "validation SR area":  # scipy's trapezoid over the sorted updates, over their span
            curves = [sorted((v["update"], v["SR"]) for v in r["validation"]) for r in truth[method]]
            return [integrate.trapezoid([y for _, y in c], [x for x, _ in c]) / (c[-1][0] - c[0][0]) for c in curves]
        return [r["selected"]["overall"][name] for r in truth[method]]

    for name in ("SR", "SPL", "SR>=5", "training SR", "validation SR area", "losses/entropy"):
        got = out["pairs"]["b - a"][name]
        np.testing.assert_allclose(
            [got["diff"], got["ci_low"], got["ci_high"], got["p"]],
            hand_paired(col("a", name), col("b", name)),
            rtol=1e-9,
        )
    for name in ("SR", "SPL", "SR>=5"):
        got = out["did"]["(d - c) - (b - a)"][name]
        first = np.subtract(col("b", name), col("a", name))
        second = np.subtract(col("d", name), col("c", name))
        np.testing.assert_allclose(
            [got["diff"], got["ci_low"], got["ci_high"], got["p"]], hand_paired(first, second), rtol=1e-9
        )
    sr_a = col("a", "SR")
    assert " / ".join(f"{x:.1f}" for x in sr_a) in printed
    assert f"{out['pairs']['b - a']['SR']['diff']:+.2f}" in printed
    assert "1.50M / 1003" in printed  # the experience of seed 3


def test_the_validation_area_is_the_curves_mean_over_its_span():
    from experiments.reporting.report import validation_area

    # (500, 10) -> (1000, 30) -> (2000, 20), given out of order: (20 * 500 + 25 * 1000) / 1500
    curve = [{"update": 1000, "SR": 30.0}, {"update": 500, "SR": 10.0}, {"update": 2000, "SR": 20.0}]
    assert validation_area(curve) == pytest.approx((20 * 500 + 25 * 1000) / 1500)
    assert validation_area([{"update": 500, "SR": 12.5}]) == 12.5
    assert np.isnan(validation_area([]))
    assert np.isnan(validation_area([{"update": 500, "SR": None}, {"update": 1000, "SR": 4.0}]))


def test_bad_input_says_what_is_wrong(tmp_path):
    with pytest.raises(errors.UserError, match="not a sweep folder"):
        compare.main(compare.Args(run=tmp_path))
    write_sweep(tmp_path / "one", np.random.default_rng(1), methods=("a", "b"))
    write_sweep(tmp_path / "one", np.random.default_rng(2), methods=("c",), seeds=(0, 1, 2, 3))
    for pairs, says in (
        (("a:x",), "'x' is not a finished method of this sweep; it has a, b, c"),
        (("a-b",), "give 2 method names"),
        (("a:c",), "different seeds"),
    ):
        with pytest.raises(errors.UserError, match=says):
            compare.main(compare.Args(run=tmp_path / "one", pairs=pairs))


def test_the_robust_table_of_the_pairs_matches_a_hand_computation(tmp_path, capsys):
    truth = write_sweep(tmp_path, np.random.default_rng(1))
    out = compare.main(compare.Args(run=tmp_path, pairs=("a:b", "a:c")))
    printed = capsys.readouterr().out
    sr = {m: np.array([r["selected"]["overall"]["SR"] for r in truth[m]]) for m in "abc"}
    p_values = [sp.ttest_rel(sr[m], sr["a"]).pvalue for m in "bc"]
    # Holm over the two pairs: the smaller p doubled, the larger kept (never below the first)
    first = min(1.0, 2 * min(p_values))
    adjusted = {m: first if p == min(p_values) else max(first, p) for m, p in zip("bc", p_values)}
    for m, p_holm in adjusted.items():
        robust = out["pairs"][f"{m} - a"]["robust"]["SR"]
        middle = lambda x: np.sort(x)[1:3].mean()  # noqa: E731  4 seeds: the IQM is the middle two's mean
        assert robust["iqm_a"][0] == pytest.approx(middle(sr["a"])) and robust["iqm_b"][0] == pytest.approx(
            middle(sr[m])
        )
        wins = np.mean([(y > x) + 0.5 * (y == x) for y in sr[m] for x in sr["a"]])
        assert robust["probability_of_improvement"][0] == pytest.approx(wins)
        assert robust["p_holm"] == pytest.approx(p_holm)
        d = sr[m] - sr["a"]
        assert robust["mde"] == pytest.approx(stats.minimum_detectable_effect(d.std(ddof=1), len(d)))
    assert "What these seeds can tell" in printed and "P(B > A)" in printed


def test_the_ceiling_and_the_share_closed_are_reported_only_where_the_ceiling_is_resolved(tmp_path, capsys):
    """`--ceiling A:B:C`: C - A with its interval and (B - A) / (C - A) with its bootstrap
    interval where C - A is resolved, "ceiling not resolved" where not."""
    import json

    from experiments import compare

    srs = {
        "crit": [50.0, 52.0, 48.0, 51.0, 49.0],
        "fore": [52.0, 55.0, 49.0, 53.0, 51.0],
        "orac": [60.0, 64.0, 56.0, 62.0, 58.0],
    }
    spls = {"crit": [20.0] * 5, "fore": [21.0] * 5, "orac": [20.5, 19.0, 21.0, 19.5, 20.0]}
    for arm in srs:
        folder = tmp_path / "methods" / arm
        folder.mkdir(parents=True)
        per_seed = [
            {
                "seed": s,
                "selected": {"overall": {"SR": srs[arm][s], "SPL": spls[arm][s], "SR>=5": 0.0}},
                "training_success_rate": [0.5] * 10,
            }
            for s in range(5)
        ]
        (folder / "results.json").write_text(json.dumps({"updates": 10, "results": per_seed}))
    out = compare.main(compare.Args(run=tmp_path, ceiling=("crit:fore:orac",)))
    sr, spl = out["ceiling"]["orac - crit"]["SR"], out["ceiling"]["orac - crit"]["SPL"]
    assert sr["resolved"] and sr["ceiling"] == pytest.approx(10.0) and sr["share"] == pytest.approx(10 / 50)
    assert sr["share_low"] <= sr["share"] <= sr["share_high"]
    assert not spl["resolved"] and "share" not in spl
    md = capsys.readouterr().out
    assert "ceiling not resolved" in md and "0.20 [" in md
