"""docs/ceiling.md's channels study (issue 68, docs/plans/ceiling_channels.md): what its
archives' runs record (settings, seeds, commits, selected updates, the runs that repeat
earlier ones bit for bit, the first parting of stage 4's two runs) and the figures its hand
prose quotes. Its tables, pairs, verdicts and the plan's rules 1-3, and docs/results.md's
figures of its stages, are generated blocks (experiments/reporting/pages/ceiling_md.py,
results_md.py), held by the drift test (tests/experiments/test_regenerate.py), not
recomputed here."""

from pathlib import Path

import numpy as np
import pytest
import study_data

from experiments.reporting import report
from experiments import rundir

REPO = Path(__file__).resolve().parents[2]
CRITIC = "a3c+critic@learning_rate=3e-4"
COMPASS = "a3c+compass@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0"
START = "a3c+startcompass@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0"


def curve_means(per_seed: list[dict]) -> list[float]:
    """The mean over seeds of the validation SR at each of 500, ..., 3000 updates."""
    updates = [[v["update"] for v in r["validation"]] for r in per_seed]
    assert all(u[:6] == [500, 1000, 1500, 2000, 2500, 3000] for u in updates)
    return [float(np.mean([r["validation"][i]["SR"] for r in per_seed])) for i in range(6)]


def flat_doc() -> str:
    return " ".join((REPO / "docs" / "ceiling.md").read_text().split())


def test_stage_1_runs_as_the_plan_sets(tmp_path):
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
    # "The critic reproduces bit for bit": the range-4 study's critic (79dce9c), seed for seed
    earlier = rundir.sweep_results(
        study_data.unpack("ceiling_range4.tar.xz", tmp_path / "range4", (CRITIC, "a3c+oracle@learning_rate=3e-4"))
    )
    for column in ("SR", "SPL"):
        assert list(report.values(results[CRITIC], column)) == list(report.values(earlier[CRITIC], column))
    assert all(r["selected_update"] == 3000 for arm in results for r in results[arm])  # "its last model"
    # the per-step compass's last 500 updates, quoted in prose (issue 81: once +3.6 from the
    # rounded table)
    means = curve_means(results[COMPASS])
    last = f"(+{means[5] - means[4]:.1f} over the last 500: {means[5]:.2f} - {means[4]:.2f})"
    assert last in flat_doc(), last


# ---------------------------------------------------------------------- stage 2
ENC = "a3c+oracle@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0"
MLP_CRITIC = "a3c+critic@learning_rate=3e-4,imagination_input=mlp"
MLP = "a3c+oracle@learning_rate=3e-4,imagination_input=mlp,sigma2_max=0"
HEAD = "a3c+oracle@learning_rate=3e-4,sigma2_max=0"
STAGE2 = (CRITIC, ENC, MLP_CRITIC, MLP, HEAD)  # the sweep's order


def test_stage_2_runs_as_the_plan_sets(tmp_path):
    if not (study_data.DATA / "channels_stage2.tar.xz").exists():
        pytest.skip("channels_stage2.tar.xz: not run yet")
    root = study_data.unpack("channels_stage2.tar.xz", tmp_path, STAGE2)
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
    results = rundir.sweep_results(root)
    assert all([r["seed"] for r in results[arm]] == [0, 1, 2, 3, 4] for arm in results)
    assert all(r["selected_update"] == 3000 for arm in results for r in results[arm])  # "every seed selected 3000"
    # Stage 1's critic, copied by --reuse: the same numbers
    first = rundir.sweep_results(
        study_data.unpack("channels_stage1.tar.xz", tmp_path / "stage1", (CRITIC, COMPASS, START))
    )
    assert list(report.values(first[CRITIC], "SR")) == list(report.values(results[CRITIC], "SR"))
    # "The head arm reproduces bit for bit": the range-4 study's noise-off oracle (79dce9c)
    earlier = rundir.sweep_results(
        study_data.unpack(
            "ceiling_range4_noiseoff.tar.xz", tmp_path / "noiseoff", (CRITIC, "a3c+oracle@learning_rate=3e-4", HEAD)
        )
    )
    for column in ("SR", "SPL"):
        assert list(report.values(results[HEAD], column)) == list(report.values(earlier[HEAD], column))
    # the goal-view arms ran on stage 1's seeds (docs/results.md pairs them with its start compass)
    assert all([r["seed"] for r in results[arm]] == [r["seed"] for r in first[START]] for arm in (ENC, MLP, HEAD))


# ---------------------------------------------------------------------- stage 3
def test_stage_3_runs_as_the_plan_sets(tmp_path):
    """Stage 3, the budget branch (docs/data/channels_stage3.tar.xz): the critic and the best
    channel, `head`, extended from stage 2's 3000 updates to 9000, each seed from its own
    3000-update results (kept beside as results_3000_updates.json, which are stage 2's); the
    selected updates the prose quotes."""
    if not (study_data.DATA / "channels_stage3.tar.xz").exists():
        pytest.skip("channels_stage3.tar.xz: not run yet")
    root = study_data.unpack("channels_stage3.tar.xz", tmp_path, (CRITIC, HEAD))
    for arm in (CRITIC, HEAD):
        config = rundir.read_json(rundir.arm_folder(root, arm) / "run.json")["config"]
        assert config["priors"] is True and config["perception_range"] == 4.0 and config["learning_rate"] == 3e-4
        assert config["num_updates"] == 9000 and config["setup"] == "savn"
    assert rundir.read_json(rundir.arm_folder(root, HEAD) / "run.json")["config"]["sigma2_max"] == 0
    results = rundir.sweep_results(root)
    assert all([r["seed"] for r in results[arm]] == [0, 1, 2, 3, 4] for arm in results)
    stage2 = rundir.sweep_results(study_data.unpack("channels_stage2.tar.xz", tmp_path / "stage2", STAGE2))
    for arm in (CRITIC, HEAD):
        before = rundir.read_json(rundir.arm_folder(root, arm) / rundir.kept_results(3000), ("results",))["results"]
        for column in ("SR", "SPL"):  # the runs were copied from stage 2, then extended
            assert list(report.values(before, column)) == list(report.values(stage2[arm], column))
    flat = flat_doc()
    for arm, label in ((CRITIC, "a3c+critic"), (HEAD, "a3c+oracle through `head` (privileged)")):
        line = f"{label} selected updates {', '.join(str(r['selected_update']) for r in results[arm])}"
        assert line in flat, line


# ---------------------------------------------------------------------- stage 4
def first_difference(a: list, b: list) -> int | None:
    """The first update at which two training curves differ (None: they never do)."""
    return next((i for i, (x, y) in enumerate(zip(a, b, strict=True)) if x != y), None)


def test_stage_4_runs_as_the_plan_sets(tmp_path):
    """Stage 4, today's rooms (docs/data/channels_rooms.tar.xz): the critic and the best
    channel, `head`, at quick's budget without priors or range, from the plan's worktree; the
    selected updates the prose quotes, and the claim that neither arm repeats its 2498418 run
    (docs/data/ceiling_savn_epyc.tar.xz): the training curves agree for the first 74 to 325
    updates, then part."""
    if not (study_data.DATA / "channels_rooms.tar.xz").exists():
        pytest.skip("channels_rooms.tar.xz: not run yet")
    root = study_data.unpack("channels_rooms.tar.xz", tmp_path, (CRITIC, HEAD))
    for arm in (CRITIC, HEAD):
        run = rundir.read_json(rundir.arm_folder(root, arm) / rundir.RUN_FILE)
        assert [c[:7] for c in run["commits"]] == ["431bbf4"]  # the worktree's commit
        config = run["config"]
        assert config["priors"] is False and config.get("perception_range") is None
        assert config["num_updates"] == 3000 and config["setup"] == "savn" and config["learning_rate"] == 3e-4
        assert config["room_types"] == [] and config["layout"] == "room"
    assert rundir.read_json(rundir.arm_folder(root, HEAD) / "run.json")["config"]["sigma2_max"] == 0
    results = rundir.sweep_results(root)
    assert all([r["seed"] for r in results[arm]] == [0, 1, 2, 3, 4] for arm in results)
    # "Every oracle seed selected its last model (update 3000) and the critic's four of five"
    assert [r["selected_update"] for r in results[HEAD]] == [3000] * 5
    assert sorted(r["selected_update"] for r in results[CRITIC]) == [2500, 3000, 3000, 3000, 3000]
    # neither arm repeats its 2498418 run: the curves agree at first, then part
    earlier = study_data.unpack(
        "ceiling_savn_epyc.tar.xz", tmp_path / "epyc", (CRITIC, "a3c+oracle@learning_rate=3e-4", HEAD)
    )
    firsts = []
    for arm in (CRITIC, HEAD):
        now = rundir.read_json(rundir.arm_folder(root, arm) / rundir.RESULTS_FILE)
        before = rundir.read_json(rundir.arm_folder(earlier, arm) / rundir.RESULTS_FILE)
        # the same platform, so the parting is the start's, not the machine's
        assert [r["numerics"] for r in now["results"]] == [r["numerics"] for r in before["results"]]
        firsts += [first_difference(a, b) for a, b in zip(now["curves"], before["curves"], strict=True)]
    assert None not in firsts, "a curve repeats its 2498418 run to the end: the docs say they part"
    assert f"for its first {min(firsts)} to {max(firsts)} updates, then the two part" in flat_doc()
