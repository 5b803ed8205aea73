"""The priors study's files (docs/data/priors_*.tar.xz and priors_probe_*.json) hold the runs
docs/priors.md describes. docs/priors.md's tables and verdicts, and docs/results.md's figures
of the study, are generated from them (experiments/reporting/pages/; the drift test,
tests/experiments/test_regenerate.py, fails when they differ); the layouts themselves:
tests/envs/test_priors.py."""

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
    selected model tested on the same episodes, and experiments.compare reads them."""

    import study_data
    from experiments import rundir
    from experiments import compare

    root = study_data.unpack(archive, tmp_path, arms)
    sweep = rundir.read_json(root / "sweep.json")
    assert sweep["config"]["priors"] is True and sweep["seeds"] == 5
    assert sweep.get("setup", "savn") == ("org" if archive == "priors_org.tar.xz" else "savn")
    pairs = [(arms[0], arms[1]), (arms[0], arms[2]), (arms[1], arms[2])]
    out = compare.main(compare.Args(run=root, pairs=tuple(f"{a}:{b}" for a, b in pairs)))
    assert sorted(out["pairs"]) == sorted(f"{b} - {a}" for a, b in pairs)
    capsys.readouterr()
    results = rundir.sweep_results(root)
    assert all([r["seed"] for r in results[arm]] == [0, 1, 2, 3, 4] for arm in arms)
    episodes = {r["selected"]["overall"]["episodes"] for arm in arms for r in results[arm]}
    assert len(episodes) == 1, episodes  # the same test episodes for every arm and seed


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
    selected models played with sampled actions), on seeds 0-4 of each (docs/priors.md's table
    and results.md's sentence are generated from the same files)."""
    import json

    import study_data
    from experiments import rundir

    study_data.extract("priors_org_control.tar.xz", tmp_path)
    root = tmp_path / "priors_org_control"
    sampled = json.loads((root / "org_sampled.json").read_text())
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
