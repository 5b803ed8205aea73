"""docs/results.md's page module (experiments/reporting/pages/results_md.py): its pairs are what
the sweep's own report computes (`report.paired_report`, which `experiments.compare` prints),
Holm's correction included, and its readers pick the arms and files they name."""

import pytest

from experiments.reporting import report
from experiments.reporting.pages import results_md as R
from experiments.reporting.registry import Archives


@pytest.fixture(scope="module")
def archives():
    return Archives()


def test_a_familys_rows_are_the_sweeps_paired_report(archives):
    """The first sweep's three pairs: SR and SPL intervals, P(B > A), Holm's p over the three
    and the MDE are `report.paired_report`'s on the same arms."""
    results = {arm: archives.results(R.FIRST, arm) for arm in (R.A3, R.F3, R.C3)}
    pairs = [(R.A3, R.F3), (R.A3, R.C3), (R.C3, R.F3)]
    _, out = report.paired_report(results, pairs, ["SR", "SPL"])
    sr, spl = R.judged(archives, R.FIRST_PAIRS, "SR"), R.judged(archives, R.FIRST_PAIRS, "SPL")
    for (a, b), v, w in zip(pairs, sr, spl):
        theirs = out[f"{b} - {a}"]
        assert v.diff == pytest.approx(theirs["SR"]["diff"]) and w.ci95[0] == pytest.approx(theirs["SPL"]["ci_low"])
        assert v.p == pytest.approx(theirs["robust"]["SR"]["p_holm"])
        assert w.p == pytest.approx(theirs["robust"]["SPL"]["p_holm"])
        assert v.mde == pytest.approx(theirs["robust"]["SR"]["mde"])
    rows = R.family_table(archives, R.FIRST_PAIRS).splitlines()[2:]
    first = out[f"{R.F3} - {R.A3}"]["robust"]["SR"]
    poi = first["probability_of_improvement"]
    assert f"| {poi[0]:.2f} [{poi[1]:.2f}, {poi[2]:.2f}] |" in rows[0]


def test_the_readers_name_their_arms_and_files(archives):
    """`Unchosen` is the candidate validation did not choose; `AT_3000` reads an extended
    run's results at its first budget (3000 updates, the first sweep's)."""
    chosen = R.Ref(R.TUNE, R.Chosen((R.A3, R.A10))).name(archives)
    assert chosen == R.A10 and R.Ref(R.TUNE, R.Unchosen((R.A3, R.A10))).name(archives) == R.A3
    assert R.Ref(R.THREE_X, R.F3, R.AT_3000).results(archives) == archives.results(R.FIRST, R.F3)
    with pytest.raises(ValueError, match="same seeds"):
        R.Pair(R.Ref(R.THREE_X, R.A3), R.Ref(R.REPLICATION, R.F3)).differences(archives, "SR")


def test_a_level_verdict_beyond_the_quoted_interval_gives_its_90_percent_interval(archives):
    """The rule's "level" rests on the 90% interval; where the quoted 95% one reaches past the
    margin, the words say the 90% one."""
    spl = R.judged(archives, R.THREE_X_PAIRS, "SPL")[0]  # +0.6 [-3.3, +4.5]
    assert spl.word == "level" and spl.ci95[1] > spl.margin
    assert R.words(spl).startswith("level within ±3.8 (90% CI [")
    sr = R.judged(archives, R.THREE_X_PAIRS, "SR")[0]  # +0.9 [-0.9, +2.6]
    assert R.words(sr) == "level within ±3.8"
