"""The house study's files: what docs/houses.md says was run.

The study (three arms, seeds 0-4, `--preset house`) trained on a lent GPU; its sweep folder,
without checkpoints, is kept as docs/data/house_study.tar.xz. docs/houses.md's tables and
verdicts are generated from it (experiments/reporting/pages/houses_md.py; the drift test,
tests/experiments/test_regenerate.py, fails when they differ). This checks the run's records
(the preset, seeds, machine, episodes, the probe's and failure reports' settings), as
`experiments.compare` reads the archive; results.md's figures of it are generated too.
"""

from __future__ import annotations

import json
import tarfile

import pytest
import study_data

from experiments import rundir

METHODS = ("a3c", "a3c+critic", "a3c+foresit")


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> dict[str, list[dict]]:
    """Each method's per-seed results, read from the unpacked archive as `experiments.compare` reads a sweep."""
    return rundir.sweep_results(study_data.unpack("house_study.tar.xz", tmp_path_factory.mktemp("house"), METHODS))


def test_the_archive_holds_five_paired_seeds_of_each_arm(study):
    for results in study.values():
        assert [r["seed"] for r in results] == [0, 1, 2, 3, 4]
        assert all(r["selected"]["overall"]["episodes"] == 1000 for r in results)


def test_the_run_is_what_houses_md_says(study):
    """`--preset house`, the three arms, five seeds, 12,000 updates on the lent H100 (jax
    0.11.2), the probe's 40 windows and 100 episodes per room type, the failures' test split at
    250 episodes per room type."""
    spec = study_data.read_archive_json("house_study.tar.xz")["house_study/sweep.json"]
    assert (spec["preset"], spec["methods"], spec["seeds"], spec["setup"]) == ("house", list(METHODS), 5, "savn")
    for results in study.values():
        for r in results:
            assert r["validation"][-1]["update"] == 12000 and r["counts"]["frames/useful"] == 6_144_000
            (platform,) = [n["platform"] for n in r["numerics"]]
            assert (platform["backend"], platform["jax"]) == ("gpu", "0.11.2") and "H100" in platform["device"]
    with tarfile.open(study_data.DATA / "house_study.tar.xz") as tar:
        probe = json.load(tar.extractfile("house_study/probe.json"))
        failures = {m: json.load(tar.extractfile(f"house_study/failures_{m.split('+')[-1]}.json")) for m in METHODS}
    assert (probe["windows"], probe["episodes_per_room"], list(probe["methods"])) == (40, 100, ["a3c+foresit"])
    assert [r["seed"] for r in probe["methods"]["a3c+foresit"]] == [0, 1, 2, 3, 4]
    for method, report_ in failures.items():
        assert (report_["split"], report_["episodes_per_room"], list(report_["methods"])) == ("test", 250, [method])
        assert [r["all"]["episodes"] for r in report_["methods"][method]] == [1000] * 5
