"""The house study's figures in docs/results.md and docs/houses.md are those of its files.

The study (three arms, seeds 0-4, `--preset house`) trained on a lent GPU; its sweep folder,
without checkpoints, is kept as docs/data/house_study.tar.xz. This reads it back as
`experiments.compare` and the sweep's tables do, recomputes the quoted means and paired
intervals with `experiments.reporting.stats`, and checks that results.md and houses.md print them.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import study_data

from experiments import compare, rundir
from experiments.reporting import report, stats

REPO = Path(__file__).resolve().parents[2]
METHODS = ("a3c", "a3c+critic", "a3c+foresit")


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> dict[str, list[dict]]:
    """Each method's per-seed results, read from the unpacked archive as `experiments.compare` reads a sweep."""
    return rundir.sweep_results(study_data.unpack("house_study.tar.xz", tmp_path_factory.mktemp("house"), METHODS))


def sr(results: list[dict]):
    return report.values(results, "SR")


def interval(p: dict) -> str:
    return f"{p['diff']:+.1f} [{p['ci_low']:+.1f}, {p['ci_high']:+.1f}]".replace("+-", "-")


def test_the_archive_holds_five_paired_seeds_of_each_arm(study):
    for results in study.values():
        assert [r["seed"] for r in results] == [0, 1, 2, 3, 4]
        assert all(r["selected"]["overall"]["episodes"] == 1000 for r in results)


def test_results_md_and_houses_md_quote_the_study(study):
    """results.md's summary table of the houses (once the README's) and houses.md's print the
    study's means and paired intervals."""
    summary = (REPO / "docs" / "results.md").read_text()
    houses = (REPO / "docs" / "houses.md").read_text()
    for method in METHODS:
        s = stats.summary(sr(study[method]))
        assert f"{s['mean']:.1f} ± {s['std']:.1f}" in summary, method
        assert f"| {method} | {s['mean']:.1f} ± {s['std']:.1f} |" in houses, method
    for base, other in (("a3c", "a3c+critic"), ("a3c", "a3c+foresit"), ("a3c+critic", "a3c+foresit")):
        pair = interval(stats.paired(sr(study[base]), sr(study[other])))
        assert pair in summary and pair in houses, (other, base, pair)


def test_houses_md_by_length_pairs_are_the_sweeps(study):
    """Each bucket's row of houses.md's by-length table ends with the pairs the sweep's
    table1.md computes (`report.paired_by_length`): against the critic, then against a3c."""
    houses = (REPO / "docs" / "houses.md").read_text()
    against_critic = report.paired_by_length(study, "a3c+critic", "a3c+foresit")
    against_a3c = report.paired_by_length(study, "a3c", "a3c+foresit")
    for (bucket, episodes, critic, _), (_, _, a3c, _) in zip(against_critic, against_a3c):
        assert f"| {bucket} | {episodes} |" in houses, bucket
        assert f"| {interval(critic)} | {interval(a3c)} |" in houses, bucket


def test_houses_md_quotes_the_robust_statistics_of_the_archive(study, tmp_path, capsys):
    """The IQM / P(B > A) / Holm / MDE table of houses.md is experiments.compare's on the archive."""
    root = study_data.unpack("house_study.tar.xz", tmp_path, METHODS)
    pairs = (("a3c", "a3c+critic"), ("a3c", "a3c+foresit"), ("a3c+critic", "a3c+foresit"))
    out = compare.main(compare.Args(run=root, pairs=tuple(f"{a}:{b}" for a, b in pairs)))
    capsys.readouterr()
    houses = (REPO / "docs" / "houses.md").read_text()
    for a, b in pairs:
        r = out["pairs"][f"{b} - {a}"]["robust"]["SR"]
        cells = [f"{x[0]:.1f} [{x[1]:.1f}, {x[2]:.1f}]" for x in (r["iqm_a"], r["iqm_b"])]
        poi = r["probability_of_improvement"]
        row = (
            f"| {b} - {a} | {cells[0]} | {cells[1]} | {poi[0]:.2f} [{poi[1]:.2f}, {poi[2]:.2f}] | "
            f"{r['p_holm']:.3f} | {r['mde']:.1f} |"
        )
        assert row in houses, row
    mde = out["pairs"]["a3c+foresit - a3c+critic"]["robust"]["SR"]["mde"]
    assert f"{mde:.1f}" in houses  # the MDE the "cannot tell" rests on
