"""The foresight study's files, docs/data/foresight_*.json, are what `experiments.foresight`
wrote for the runs docs/foresight.md names (the tool itself: tests/experiments/test_foresight.py).
docs/foresight.md's tables and sentences are generated from them
(experiments/reporting/pages/foresight_md.py; tests/experiments/test_regenerate.py fails on
drift, and tests/experiments/test_study_pages.py checks the levers' criterion on made-up data)."""

import json
from pathlib import Path

import pytest

from experiments.reporting import foresight_bound as bound
from experiments.reporting.pages import foresight_md

DATA = Path(__file__).resolve().parents[2] / "docs" / "data"


@pytest.mark.parametrize("data_file, labels", [(f, layouts) for f, layouts in foresight_md.TABLES.values()])
def test_each_measurement_is_the_run_its_label_names(data_file, labels):
    """Each layout family of docs/data/`data_file` was measured from 20,000 resets, with
    priors and a perception range exactly where its label says so, on the layout and setup
    its key names; its results hold the turn and the bearing, split by the anchor under priors."""
    data = json.loads((DATA / data_file).read_text())
    for name, label in labels:
        args = data[name]["args"]
        assert args["resets"] == 20000 and bool(args.get("priors", False)) == ("with priors" in label)
        assert args.get("perception_range") == (float(label.split("range ")[1]) if "range" in label else None)
        assert args["layout"] == name.split("-")[0] and args["setup"] == ("org" if "org" in label else "savn")
        for what in foresight_md.WHATS:
            r = data[name]["results"][what]
            assert r["test_groups"] == (15 if args["layout"] == "house" else 20)
            assert set(r.get("subsets", {})) == (
                {"anchor in view", "anchor not in view"} if args.get("priors") else set()
            )


def test_every_measurement_is_on_the_page():
    """The page's tables cover every layout family of the three files."""
    shown = {(f, k) for f, layouts in foresight_md.TABLES.values() for k, _ in layouts}
    kept = {(f.name, k) for f in DATA.glob("foresight_*.json") for k in json.loads(f.read_text())}
    assert shown == kept


def test_the_page_reads_the_tools_feature_sets_and_bearings():
    assert foresight_md.FEATURE_SETS == bound.FEATURE_SETS and foresight_md.BEARINGS == bound.BEARINGS
