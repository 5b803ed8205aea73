"""The priors study's figures in docs/priors.md and docs/results.md are those of its files
(docs/data/priors_*.tar.xz and priors_probe_*.json; the layouts themselves:
tests/envs/test_priors.py)."""

import numpy as np
import pytest


@pytest.mark.parametrize(
    "archive, arms",
    [
        ("priors_savn.tar.xz", ("a3c", "a3c+critic@learning_rate=3e-4", "a3c+foresit@learning_rate=3e-4")),
        ("priors_org.tar.xz", ("a3c+org", "a3c+org+critic", "a3c+org+foresit")),
    ],
)
def test_docs_quote_the_study_in_rooms_with_priors(tmp_path, capsys, archive, arms):
    """docs/priors.md's pairs are what experiments.compare computes from the study's files
    (docs/data/priors_<setup>.tar.xz: the sweep folder without checkpoints), the pairs on
    the long paths too."""
    from pathlib import Path

    import study_data
    from experiments import rundir
    from experiments import compare

    root = study_data.unpack(archive, tmp_path, arms)
    assert rundir.read_json(root / "sweep.json")["config"]["priors"] is True
    pairs = [(arms[0], arms[1]), (arms[0], arms[2]), (arms[1], arms[2])]
    out = compare.main(compare.Args(run=root, pairs=tuple(f"{a}:{b}" for a, b in pairs)))
    capsys.readouterr()
    results = rundir.sweep_results(root)
    doc = (Path(__file__).resolve().parents[2] / "docs" / "priors.md").read_text()
    flat = " ".join(doc.split())

    for a, b in pairs:
        row = study_data.pair_row(out, results, a, b)
        assert row in doc, row
    long_paths = {(a, b): study_data.interval(out["pairs"][f"{b} - {a}"]["SR>=5"]) for a, b in pairs}
    if archive == "priors_savn.tar.xz":
        assert f"(L^g >= 5): {long_paths[arms[1], arms[2]]} SR" in flat
    else:
        assert f"(L^g >= 5): {long_paths[arms[0], arms[2]]}." in flat
        assert f"on the long paths {long_paths[arms[1], arms[2]]}" in flat
    # results.md's "In brief" (once the README's Results) quotes the pairs.
    summary = " ".join((Path(__file__).resolve().parents[2] / "docs" / "results.md").read_text().split())
    base, critic, foresit = (a.split("@")[0] for a in arms)
    vs_base, vs_critic = (out["pairs"][f"{arms[2]} - {a}"] for a in arms[:2])
    sr, spl = study_data.interval(vs_critic["SR"]), study_data.interval(vs_critic["SPL"])
    quotes = [
        f"{foresit} - {base} {study_data.interval(vs_base['SR'])} SR",
        f"{sr} over the critic" if archive == "priors_org.tar.xz" else f"{foresit} - {critic} {sr} SR, {spl} SPL",
    ]
    for quoted in quotes:
        assert quoted in summary, quoted


@pytest.mark.parametrize(
    "data, method",
    [("priors_probe_savn.json", "a3c+foresit@learning_rate=3e-4"), ("priors_probe_org.json", "a3c+org+foresit")],
)
def test_docs_quote_the_probes_in_rooms_with_priors(data, method):
    """docs/priors.md's probe tables and intervals are those of docs/data/priors_probe_<setup>.json
    (what `experiments.probe` wrote for the studies' ForeSIT seeds)."""
    import json
    from pathlib import Path

    import study_data
    from experiments.reporting import stats
    from study_data import interval

    repo = Path(__file__).resolve().parents[2]
    per_seed = json.loads((repo / "docs" / "data" / data).read_text())["methods"][method]
    doc = (repo / "docs" / "priors.md").read_text()
    flat = " ".join(doc.split())
    assert [r["seed"] for r in per_seed] == [0, 1, 2, 3, 4]
    for r in per_seed:
        row = study_data.probe_fit_row(r)
        assert row in doc, row
    fit = [r["items"]["fit"] for r in per_seed]
    gain = [f["ridge_r2_over_mean"] - f["category_r2_over_mean"] for f in fit]
    online = [f["r2_over_mean"] - f["category_r2_over_mean"] for f in fit]
    trained = [r["sr"]["trained"] for r in per_seed]

    def quoted(condition):
        return interval(stats.paired(trained, [r["sr"][condition] for r in per_seed]))

    if method.startswith("a3c+foresit"):
        assert f"by {min(gain):+.2f} to {max(gain):+.2f} R^2" in flat
        texts = [
            f"noise off {quoted('shuffled, noise off')} SR",
            f"untrained f_w {quoted('untrained f_w')},",
            f"with the noise off {quoted('noise off')}.",
        ]
    else:
        assert sum(g > 0 for g in gain) == 4 and f"(by up to {max(gain):+.2f})" in flat
        assert max(online) < 0 and f"every seed ({max(online):+.2f} to {min(online):+.2f})" in flat
        texts = [
            f"noise off {quoted('shuffled, noise off')} SR",
            f"untrained f_w {quoted('untrained f_w')}.",
            f"scores {quoted('sampled actions')} SR higher",
        ]
    for text in texts:
        assert text in flat, text


def test_docs_quote_the_org_control_in_both_layouts(tmp_path):
    """docs/priors.md's control for ORG's graph is what its files give
    (docs/data/priors_org_control.tar.xz: a3c on the org setup in today's rooms and in rooms
    with priors, without checkpoints, and a3c+org's selected models played with sampled
    actions): per layout the graph's gain paired by seed, and Welch's interval on the two
    layouts' per-seed gains; results.md's "In brief" (once the README's Results) quotes the last."""
    import json
    from pathlib import Path

    from scipy import stats as scipy_stats

    import study_data
    from experiments.reporting import stats
    from experiments import rundir

    study_data.extract("priors_org_control.tar.xz", tmp_path)
    root = tmp_path / "priors_org_control"
    sampled = json.loads((root / "org_sampled.json").read_text())
    repo = Path(__file__).resolve().parents[2]
    doc = (repo / "docs" / "priors.md").read_text()
    gains = {}
    for layout, folder, priors in (("today", "org_control", None), ("priors", "org_control_priors", True)):
        spec = rundir.read_json(root / folder / "sweep.json")
        assert (spec["setup"], spec["methods"], spec["seeds"], spec["config"].get("priors")) == (
            "org",
            ["a3c"],
            5,
            priors,
        )
        base = {
            r["seed"]: r["selected"]["overall"]
            for r in rundir.read_json(root / folder / "methods" / "a3c" / "results.json")["results"]
        }
        graph = {r["seed"]: r["overall"] for r in sampled[layout]}
        assert sorted(base) == sorted(graph) == [0, 1, 2, 3, 4]
        cells = []
        for col in ("SR", "SPL", "SR>=5"):
            a, b = [base[s][col] for s in range(5)], [graph[s][col] for s in range(5)]
            gains.setdefault(col, []).append(np.subtract(b, a))
            cells.append(study_data.interval(stats.paired(a, b)))
        sr = [[base[s]["SR"] for s in range(5)], [graph[s]["SR"] for s in range(5)]]
        means = " | ".join(f"{np.mean(x):.1f} ± {np.std(x, ddof=1):.1f}" for x in sr)
        name = "today's rooms" if layout == "today" else "rooms with priors"
        row = f"| {name} | {means} | " + " | ".join(cells) + " |"
        assert row in doc, row
    welch = []
    for col in ("SR", "SPL", "SR>=5"):
        today, priors = gains[col]
        r = scipy_stats.ttest_ind(priors, today, equal_var=False)
        ci = r.confidence_interval(0.95)
        welch.append(study_data.interval({"diff": priors.mean() - today.mean(), "ci_low": ci.low, "ci_high": ci.high}))
    row = "| priors - today (Welch) | | | " + " | ".join(welch) + " |"
    assert row in doc, row
    summary = " ".join((repo / "docs" / "results.md").read_text().split())
    assert f"over a3c than in today's rooms cannot be told ({welch[0]} SR;" in summary
