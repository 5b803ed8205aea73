"""The priors study's files (docs/data/priors_*.tar.xz and priors_probe_*.json) hold the runs
docs/priors.md describes, and docs/results.md's figures are theirs. docs/priors.md's tables
and verdicts are generated from the same files (experiments/reporting/pages/priors_md.py;
tests/experiments/test_regenerate.py fails on drift); the layouts themselves:
tests/envs/test_priors.py."""

import numpy as np
import pytest


@pytest.mark.parametrize(
    "archive, arms",
    [
        ("priors_savn.tar.xz", ("a3c", "a3c+critic@learning_rate=3e-4", "a3c+foresit@learning_rate=3e-4")),
        ("priors_org.tar.xz", ("a3c+org", "a3c+org+critic", "a3c+org+foresit")),
    ],
)
def test_the_study_in_rooms_with_priors_is_its_files(tmp_path, capsys, archive, arms):
    """The study's files (docs/data/priors_<setup>.tar.xz: the sweep folder without
    checkpoints) are a sweep in rooms with priors of the three arms, seeds 0-4, each seed's
    selected model tested on the same episodes; experiments.compare reads them, and
    results.md quotes what it computes."""
    from pathlib import Path

    import study_data
    from experiments import rundir
    from experiments import compare

    root = study_data.unpack(archive, tmp_path, arms)
    sweep = rundir.read_json(root / "sweep.json")
    assert sweep["config"]["priors"] is True and sweep["seeds"] == 5
    assert sweep.get("setup", "savn") == ("org" if archive == "priors_org.tar.xz" else "savn")
    pairs = [(arms[0], arms[1]), (arms[0], arms[2]), (arms[1], arms[2])]
    out = compare.main(compare.Args(run=root, pairs=tuple(f"{a}:{b}" for a, b in pairs)))
    capsys.readouterr()
    results = rundir.sweep_results(root)
    assert all([r["seed"] for r in results[arm]] == [0, 1, 2, 3, 4] for arm in arms)
    episodes = {r["selected"]["overall"]["episodes"] for arm in arms for r in results[arm]}
    assert len(episodes) == 1, episodes  # the same test episodes for every arm and seed
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
def test_the_probes_in_rooms_with_priors_are_their_files(data, method):
    """docs/data/priors_probe_<setup>.json is what `experiments.probe` wrote for the study's
    ForeSIT seeds (0-4), with the windows, episodes and conditions docs/priors.md names."""
    import json
    from pathlib import Path

    repo = Path(__file__).resolve().parents[2]
    probe = json.loads((repo / "docs" / "data" / data).read_text())
    assert list(probe["methods"]) == [method]
    assert (probe["windows"], probe["episodes_per_room"]) == (40, 100)
    per_seed = probe["methods"][method]
    assert [r["seed"] for r in per_seed] == [0, 1, 2, 3, 4]
    conditions = {"trained", "shuffled, noise off", "untrained f_w"}
    conditions |= {"noise off"} if method.startswith("a3c+foresit") else {"sampled actions"}
    assert all(conditions <= set(r["sr"]) for r in per_seed)
    episodes = [r["items"]["subgoal"]["episodes"] for r in per_seed]
    assert (min(episodes), max(episodes)) == ((679, 766) if method.startswith("a3c+foresit") else (1199, 1243))


def test_the_org_control_is_its_files(tmp_path):
    """The control for ORG's graph is its files (docs/data/priors_org_control.tar.xz: a3c on
    the org setup in today's rooms and in rooms with priors, without checkpoints, and a3c+org's
    selected models played with sampled actions), on seeds 0-4 of each; results.md's "In
    brief" (once the README's Results) quotes Welch's interval on the two layouts' per-seed
    gains (docs/priors.md's table is generated from the same files)."""
    import json
    from pathlib import Path

    from scipy import stats as scipy_stats

    import study_data
    from experiments import rundir

    study_data.extract("priors_org_control.tar.xz", tmp_path)
    root = tmp_path / "priors_org_control"
    sampled = json.loads((root / "org_sampled.json").read_text())
    repo = Path(__file__).resolve().parents[2]
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
        for col in ("SR", "SPL", "SR>=5"):
            a, b = [base[s][col] for s in range(5)], [graph[s][col] for s in range(5)]
            gains.setdefault(col, []).append(np.subtract(b, a))
    welch = []
    for col in ("SR", "SPL", "SR>=5"):
        today, priors = gains[col]
        r = scipy_stats.ttest_ind(priors, today, equal_var=False)
        ci = r.confidence_interval(0.95)
        welch.append(study_data.interval({"diff": priors.mean() - today.mean(), "ci_low": ci.low, "ci_high": ci.high}))
    summary = " ".join((repo / "docs" / "results.md").read_text().split())
    assert f"over a3c than in today's rooms cannot be told ({welch[0]} SR;" in summary
