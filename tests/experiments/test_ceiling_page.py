"""docs/ceiling.md's page module (experiments/reporting/pages/ceiling_md.py): a declared
family is judged with Holm's adjusted p-values, and the plan's rules 1 and 2
(docs/plans/ceiling_channels.md) read the rule's figures as the plan states them, on a
hand-made archive."""

import json
import tarfile

import numpy as np
import pytest

from experiments.reporting import registry, stats
from experiments.reporting.pages import ceiling_md
from experiments.reporting.verdicts import verdict


def seed(s: int, sr: float) -> dict:
    return {"seed": s, "selected": {"overall": {"SR": sr, "SPL": sr / 2}}}


@pytest.fixture
def archives(tmp_path):
    base = [60.0, 62.0, 58.0, 61.0, 59.0]
    arms = {
        "base": base,
        "b": [x + d for x, d in zip(base, (2.0, 4.0, 0.5, 3.0, 1.0))],  # p 0.031 alone
        "c": [x + d for x, d in zip(base, (2.0, 4.0, 0.3, 3.0, 0.8))],  # p 0.042 alone
    }
    for arm, values in arms.items():
        folder = tmp_path / "sweep" / "methods" / arm
        folder.mkdir(parents=True)
        (folder / "results.json").write_text(json.dumps({"results": [seed(i, v) for i, v in enumerate(values)]}))
    (tmp_path / "data").mkdir()
    with tarfile.open(tmp_path / "data" / "hand.tar.xz", "w:xz") as tar:
        tar.add(tmp_path / "sweep", arcname="sweep")
    return registry.Archives(tmp_path / "data")


def test_a_declared_family_is_judged_with_holms_p(archives):
    pairs = [
        ceiling_md.pair("b - base", "hand.tar.xz", "base", "b"),
        ceiling_md.pair("c - base", "hand.tar.xz", "base", "c"),
    ]
    alone = ceiling_md.Family(tuple(pairs)).judged(archives, "SR")
    family = ceiling_md.Family(tuple(pairs), declared=True).judged(archives, "SR")
    raw = [stats.paired(np.zeros(5), p.differences(archives, "SR"))["p"] for p in pairs]
    assert [v.p for v in alone] == pytest.approx(raw)
    assert [v.p for v in family] == pytest.approx(list(stats.holm(raw)))
    assert [v.figures() for v in alone] == [v.figures() for v in family]  # the same intervals
    assert [v.word for v in alone] == ["helps", "helps"] and all(ceiling_md.rule_2(v) == "resolved" for v in alone)
    # in the family, Holm's p of each is at least 0.05: neither gain holds, by the rule or by rule 2
    assert all(v.ci95[0] > 0 and v.p >= 0.05 for v in family)
    assert [v.word for v in family] == ["level", "level"]  # small gains: inside the margin, not resolved
    assert [ceiling_md.rule_2(v) for v in family] == ["not resolved", "not resolved"]


def test_rule_1_asks_the_lower_end_to_reach_the_mde():
    far = verdict([10.0, 11.0, 12.0, 13.0, 14.0], "SR", registry.PAPER_MARGIN)
    near = verdict([1.0, 3.0, 0.5, 2.0, 1.5], "SR", registry.PAPER_MARGIN)
    assert far.ci95[0] >= far.mde and ceiling_md.rule_1(far) == "passes"
    assert near.word == "helps" and near.ci95[0] < near.mde and ceiling_md.rule_1(near) == "does not pass"


def test_every_block_names_its_page():
    assert {file for file, _ in ceiling_md.BLOCKS.values()} == {"docs/ceiling.md"}
