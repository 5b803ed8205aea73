"""docs/ceiling.md's channels study (issue 68, docs/plans/ceiling_channels.md) is what its
archives compute: stage 1 (docs/data/channels_stage1.tar.xz, the critic and the two
compasses through `encoder`, rooms with priors at range 4, seeds 0-4, no checkpoints): every
arm's row, each compass's pair with the critic, and the plan's verdict on each (a compass
passes if its SR interval's lower bound is at least the pair's MDE), as the docs word it."""

from pathlib import Path

import pytest
import study_data
from test_ceiling_data import arm_row

from experiments import compare
from experiments.reporting import report
from experiments.running import rundir

REPO = Path(__file__).resolve().parents[1]
CRITIC = "a3c+critic@learning_rate=3e-4"
COMPASS = "a3c+compass@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0"
START = "a3c+startcompass@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0"
LABELS = {CRITIC: "a3c+critic, rooms with priors, range 4 (channels study)",
          COMPASS: "a3c+compass through `encoder` (privileged), per step",
          START: "a3c+startcompass through `encoder` (privileged), held from the start"}  # fmt: skip


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
    results = report.load(root)
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
        row = (f"| {name} - a3c+critic | {study_data.interval(pair['SR'])} | {study_data.interval(pair['SPL'])} | "
               f"{mde} | {'passes' if passes(pair) else 'does not pass'} |")
        assert row in doc, row
    start = out["pairs"][f"{START} - {CRITIC}"]
    assert start["SPL"]["ci_low"] > 0 and start["SR"]["ci_low"] < 0 < start["SR"]["ci_high"]  # the docs' words
    assert f"+4.4 [+1.9, +6.8] SPL, a gain that excludes 0" in flat and study_data.interval(start["SPL"]) == "+4.4 [+1.9, +6.8]"
    # "The critic reproduces bit for bit": the range-4 study's critic (79dce9c), seed for seed
    earlier = report.load(study_data.unpack("ceiling_range4.tar.xz", tmp_path / "range4", (CRITIC,
                                            "a3c+oracle@learning_rate=3e-4")))  # fmt: skip
    for column in ("SR", "SPL"):
        assert list(report.values(results[CRITIC], column)) == list(report.values(earlier[CRITIC], column))
    assert all(r["selected_update"] == 3000 for arm in results for r in results[arm])  # "its last model"
    # The README's plain words: the per-step compass "adds about 26 SR points", the start compass "adds little".
    readme = " ".join((REPO / "README.md").read_text().split())
    compass = out["pairs"][f"{COMPASS} - {CRITIC}"]["SR"]
    assert round(compass["diff"]) == 26 and compass["ci_low"] > 20 and "adds about 26 SR points" in readme
    assert start["SR"]["ci_low"] < 0 and "one held from the start adds little" in readme
    assert study_data.readme_links("stage 1")
