"""experiments.foresight: the bound recovers a planted relation between the target and what
the view shows, reports about 0 without one, and the labels of real starts."""

import numpy as np
import pytest

from experiments import foresight
from experiments.reporting import foresight_bound as bound

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
    data = bound.features(sem, depth, target, CLASSES, TARGETS, STRUCTURAL)
    walls = sem == 1
    more_right = walls[..., WIDTH // 2 :].sum((1, 2)) > walls[..., : WIDTH // 2].sum((1, 2))
    label = side if planted else more_right.astype(int)
    data.update(turn=label, group=rng.integers(0, groups, size=n))
    return data


@pytest.mark.parametrize("planted", [True, False])
def test_the_bound_recovers_a_planted_relation_and_reports_zero_without_one(planted):
    rng = np.random.default_rng(0)
    train, test = synthetic(rng, 1500, planted), synthetic(rng, 1500, planted)
    test["group"] = test["group"] + 100  # held-out groups
    r = bound.foresight_bound(train, test, "turn")
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
    r = bound.foresight_bound(train, test, "turn")
    assert (r["train_samples"], r["test_samples"]) == (550, 500)
    kept = test["turn"][test["turn"] >= 0]  # the shares count the kept test rows only
    assert r["test_shares"] == pytest.approx([np.mean(kept == 0), np.mean(kept == 1)])


@pytest.mark.parametrize(
    "offset, heading, sector",
    [
        ((-3, 0), 0, "ahead"),
        ((0, 3), 0, "right"),
        ((3, 0), 0, "behind"),
        ((0, -3), 0, "left"),
        ((0, 3), 2, "ahead"),
        ((-3, 0), 2, "left"),
        ((-2, 2), 1, "ahead"),
        ((2, 2), 1, "right"),
        ((-3, 1), 0, "ahead"),
        ((-1, 3), 0, "right"),
        ((3, -1), 6, "left"),
    ],
)
def test_bearing_sectors_by_hand(offset, heading, sector):
    assert bound.BEARINGS[bound.bearing_sector(np.array(offset), heading)] == sector


def test_cluster_bootstrap_is_the_groups_spread():
    """Groups of identical values: the interval is the spread of group means, not the
    (much narrower) spread of the rows."""
    values = np.repeat([0.0, 1.0], 500)
    groups = np.repeat([0, 1], 500)
    lo, hi = bound.cluster_bootstrap(values, groups, np.random.default_rng(0))
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


def test_subsets_split_the_gain_where_the_relation_can_show():
    """A planted relation visible on half of the rows only (the anchor drawn in view or
    not): the gain is large on the rows where it shows, about 0 on the others, and the
    subsets' rows add up to the whole."""
    rng = np.random.default_rng(2)
    train, test = synthetic(rng, 2000, True), synthetic(rng, 2000, True)
    for data in (train, test):
        hidden = np.arange(2000) % 2 == 1  # these rows' label is a coin the view cannot show
        data["turn"] = np.where(hidden, rng.integers(0, 2, 2000), data["turn"])
        data["subsets"] = {"shown": ~hidden, "hidden": hidden}
    test["group"] = test["group"] + 100
    r = bound.foresight_bound(train, test, "turn")
    shown, hidden = r["subsets"]["shown"], r["subsets"]["hidden"]
    assert shown["samples"] + hidden["samples"] == r["test_samples"] == 2000
    assert shown["gain"] > 0.3 and shown["gain_ci"][0] > 0.2 and abs(hidden["gain"]) < 0.06
    np.testing.assert_allclose(0.5 * (shown["gain"] + hidden["gain"]), r["gain"])


def test_anchor_in_view_reads_the_relation_table():
    from envs import catalog as C

    cats = C.categories("savn")
    counter = C.furniture_sem("savn", C.FURNITURE_KINDS.index("CounterTop"))
    bed = C.furniture_sem("savn", C.FURNITURE_KINDS.index("Bed"))
    sem = np.full((3, 3, 4), C.SEM_FLOOR)
    sem[0, 1, 2] = counter  # a toaster's counter in view
    sem[1, 1, 2] = bed  # a bed, which no toaster stands by
    sem[2, 1, 2] = counter  # a counter, with a pillow as the target
    target = np.array([cats.index("Toaster"), cats.index("Toaster"), cats.index("Pillow")])
    np.testing.assert_array_equal(bound.anchor_in_view(sem, target, "savn"), [True, False, False])


def test_a_perception_range_leaves_near_objects_and_all_furniture_resolved():
    """By hand: structural classes 0-3, target categories 4-5, a furniture kind 6 (7 classes);
    range 6 cells. The object at 3 cells stays, the one at 8 becomes class 7 (unresolved),
    the furniture at 9 stays; the geometry reads the unresolved one as an object (class 4 of
    its one-hot), and the sides show it as its own class."""
    sem = np.array([[[4, 5, 6, 1]]])  # [N=1, rows=1, W=4]
    depth = np.array([[[3.0, 8.0, 9.0, 2.0]]])
    seen, classes = bound.within_range(sem, depth, 6.0, 7, 2, 4)
    np.testing.assert_array_equal(seen, [[[4, 7, 6, 1]]])
    assert classes == 8
    untouched, same = bound.within_range(sem, depth, None, 7, 2, 4)
    assert untouched is sem and same == 7
    f = bound.features(seen, depth, np.array([0]), classes, 2, 4, unresolved=7)
    onehots = f["geometry"][0, : 4 * 5].reshape(4, 5)  # per pixel: nothing, wall, floor, furniture, object
    np.testing.assert_array_equal(onehots.argmax(1), [4, 4, 3, 1])
    sides = f["view"][0, f["geometry"].shape[1] :].reshape(2, classes)
    assert sides[0, 4] and sides[0, 7] and not sides[0, 5]  # left half: the near object, the unresolved one
    assert sides[1, 6] and sides[1, 1]


def test_perception_range_must_be_positive():
    from experiments.errors import UserError

    with pytest.raises(UserError, match="perception-range"):
        foresight.main(foresight.Args(perception_range=0.0, resets=100))
