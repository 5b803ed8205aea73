"""experiments.foresight: the bound recovers a planted relation between the target and what
the view shows, reports about 0 without one, and the labels of real starts."""

import numpy as np
import pytest

from experiments import foresight

pytest.importorskip("sklearn")

CLASSES, TARGETS, STRUCTURAL, WIDTH = 10, 6, 4, 8


def synthetic(rng, n, planted: bool, groups: int = 12):
    """First views of n starts: every view shows two object categories, one in each half,
    over random walls and floor. Planted: one of them is the target's anchor category
    (target + 1), and the label is the side it stands on, which only the target tells
    apart. Not planted: the label is the side with more wall, which the geometry shows."""
    sem = rng.integers(1, 3, size=(n, 3, WIDTH))  # walls and floor
    target = rng.integers(0, TARGETS, size=n)
    anchor = STRUCTURAL + (target + 1) % TARGETS
    other = STRUCTURAL + (target + 1 + rng.integers(1, TARGETS, size=n)) % TARGETS
    side = rng.integers(0, 2, size=n)
    rows = np.arange(n)
    sem[rows, 1, np.where(side == 0, 1, WIDTH - 2)] = anchor
    sem[rows, 1, np.where(side == 0, WIDTH - 2, 1)] = other
    depth = rng.uniform(0, 4, size=(n, 3, WIDTH))
    data = foresight.features(sem, depth, target, CLASSES, TARGETS, STRUCTURAL)
    walls = (sem == 1)
    more_right = walls[..., WIDTH // 2:].sum((1, 2)) > walls[..., :WIDTH // 2].sum((1, 2))
    label = side if planted else more_right.astype(int)
    data.update(turn=label, group=rng.integers(0, groups, size=n))
    return data


@pytest.mark.parametrize("planted", [True, False])
def test_the_bound_recovers_a_planted_relation_and_reports_zero_without_one(planted):
    rng = np.random.default_rng(0)
    train, test = synthetic(rng, 1500, planted), synthetic(rng, 1500, planted)
    test["group"] = test["group"] + 100  # held-out groups
    r = foresight.foresight_bound(train, test, "turn")
    assert r["train_samples"] == r["test_samples"] == 1500 and r["test_groups"] == 12
    lo, hi = r["gain_ci"]
    if planted:  # the view alone sees both categories, one on each side: a coin toss
        assert r["view"] < 0.6 and r["view + target"] > 0.95 and r["gain"] > 0.35 and lo > 0.3
    else:  # the geometry decides; the target adds nothing
        assert r["geometry"] > 0.9 and abs(r["gain"]) < 0.02 and lo <= 0 <= hi


def test_rows_labelled_minus_one_are_left_out():
    rng = np.random.default_rng(1)
    train, test = synthetic(rng, 600, True), synthetic(rng, 600, True)
    test["turn"][:100] = -1
    train["turn"][:50] = -1
    r = foresight.foresight_bound(train, test, "turn")
    assert (r["train_samples"], r["test_samples"]) == (550, 500)


@pytest.mark.parametrize("offset, heading, sector", [
    ((-3, 0), 0, "ahead"), ((0, 3), 0, "right"), ((3, 0), 0, "behind"), ((0, -3), 0, "left"),
    ((0, 3), 2, "ahead"), ((-3, 0), 2, "left"), ((-2, 2), 1, "ahead"), ((2, 2), 1, "right"),
    ((-3, 1), 0, "ahead"), ((-1, 3), 0, "right"), ((3, -1), 6, "left"),
])  # fmt: skip
def test_bearing_sectors_by_hand(offset, heading, sector):
    assert foresight.BEARINGS[foresight.bearing_sector(np.array(offset), heading)] == sector


def test_cluster_bootstrap_is_the_groups_spread():
    """Groups of identical values: the interval is the spread of group means, not the
    (much narrower) spread of the rows."""
    values = np.repeat([0.0, 1.0], 500)
    groups = np.repeat([0, 1], 500)
    lo, hi = foresight.cluster_bootstrap(values, groups, np.random.default_rng(0))
    assert lo == 0.0 and hi == 1.0


@pytest.mark.slow
def test_real_rooms_offer_about_nothing_to_foresee(capsys):
    """On today's rooms (targets on uniformly random candidate cells) the target adds
    about nothing; the CLI prints the table."""
    results = foresight.cli(["--resets", "3000"])
    for label in ("turn", "bearing"):
        r = results[label]
        assert r["test_samples"] > 1000 and r["geometry"] > r["majority"] + 0.1
        assert abs(r["gain"]) < 0.04
    assert "| turn |" in capsys.readouterr().out


def test_docs_quote_the_measured_bound_of_todays_layouts():
    """docs/foresight.md's table is docs/data/foresight_today.json (what the two commands wrote)."""
    import json
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    data = json.loads((repo / "docs" / "data" / "foresight_today.json").read_text())
    doc = (repo / "docs" / "foresight.md").read_text()
    for name, label in (("room-savn", "rooms"), ("house-savn", "houses")):
        assert data[name]["args"]["resets"] == 20000
        for what in ("turn", "bearing"):
            r = data[name]["results"][what]
            lo, hi = r["gain_ci"]
            row = (f"| {label} | {what} | {r['test_samples']} ({r['test_groups']} layouts) | "
                   + " | ".join(f"{100 * r[k]:.1f}" for k in ("majority", *foresight.FEATURE_SETS))
                   + f" | {100 * r['gain']:+.1f} [{100 * lo:+.1f}, {100 * hi:+.1f}] |")
            assert row in doc, row
