"""docs/ceiling.md's ceiling study (docs/data/ceiling_*.tar.xz and ceiling_probe_*.json): what
its archives' runs record (settings, seeds, the arms each sweep reused from another, the
selected updates) and the figures its hand prose quotes. Its tables, pairs, verdicts,
shares and probes, and docs/results.md's rows of its ceilings, are generated blocks
(experiments/reporting/pages/ceiling_md.py, results_md.py), held by the drift test
(tests/experiments/test_regenerate.py), not recomputed here."""

import json
from pathlib import Path, PurePosixPath

import pytest
import study_data

from experiments.reporting import report
from experiments.reporting.registry import STUDIES, Archives

REPO = Path(__file__).resolve().parents[2]
CRITIC, FORESIT, ORACLE = (
    "a3c+critic@learning_rate=3e-4",
    "a3c+foresit@learning_rate=3e-4",
    "a3c+oracle@learning_rate=3e-4",
)
NOISEOFF = "a3c+oracle@learning_rate=3e-4,sigma2_max=0"

# each archive's arms, in its sweep's order, and the family it ran in
SWEEPS = {
    "ceiling_savn.tar.xz": ((CRITIC, FORESIT, ORACLE), "today"),
    "ceiling_savn_noiseoff.tar.xz": ((CRITIC, FORESIT, ORACLE, NOISEOFF), "today"),
    "ceiling_savn_epyc.tar.xz": ((CRITIC, ORACLE, NOISEOFF), "today"),
    "ceiling_priors.tar.xz": ((CRITIC, FORESIT, ORACLE), "priors"),
    "ceiling_priors_epyc.tar.xz": ((CRITIC, ORACLE), "priors"),
    "ceiling_priors_noiseoff.tar.xz": ((CRITIC, ORACLE, NOISEOFF), "priors"),
    "ceiling_range4.tar.xz": ((CRITIC, ORACLE), "range4"),
    "ceiling_range4_noiseoff.tar.xz": ((CRITIC, ORACLE, NOISEOFF), "range4"),
}
# (the sweep that reused, the sweep it reused from, the arms copied)
REUSED = (
    ("ceiling_savn_noiseoff.tar.xz", "ceiling_savn.tar.xz", (CRITIC, FORESIT, ORACLE)),
    ("ceiling_savn_epyc.tar.xz", "ceiling_savn_noiseoff.tar.xz", (ORACLE, NOISEOFF)),
    ("ceiling_priors_epyc.tar.xz", "ceiling_priors.tar.xz", (ORACLE,)),
    ("ceiling_priors_noiseoff.tar.xz", "ceiling_priors_epyc.tar.xz", (CRITIC, ORACLE)),
    ("ceiling_range4_noiseoff.tar.xz", "ceiling_range4.tar.xz", (CRITIC, ORACLE)),
)


@pytest.fixture(scope="module")
def archives() -> Archives:
    return Archives(study_data.DATA)


def flat(name: str = "ceiling.md") -> str:
    return " ".join((REPO / "docs" / name).read_text().split())


def test_the_registry_names_every_archive_of_the_study():
    (ceiling,) = [s for s in STUDIES if s.name == "ceiling"]
    tars = {PurePosixPath(a).name for a in ceiling.archives if a.endswith(".tar.xz")}
    assert tars == set(SWEEPS)


@pytest.mark.parametrize("archive", sorted(SWEEPS))
def test_each_sweep_ran_its_arms_in_its_family_on_seeds_0_to_4(archive, archives):
    methods, family = SWEEPS[archive]
    records = study_data.read_archive_json(archive)
    (sweep,) = [v for k, v in records.items() if k.endswith("/sweep.json")]
    assert sweep["methods"] == list(methods)
    runs = {arm: v for arm in methods for k, v in records.items() if k.endswith(f"/methods/{arm}/run.json")}
    assert runs, f"{archive}: no arm's run record"  # an arm reused from an archive kept without it has none
    for arm in methods:
        assert [r["seed"] for r in archives.results(archive, arm)] == [0, 1, 2, 3, 4]
    for arm, run in runs.items():
        config = run["config"]
        assert config["setup"] == "savn" and config["num_updates"] == 3000 and config["learning_rate"] == 3e-4
        assert config["priors"] is (family != "today")
        assert config.get("perception_range") == (4.0 if family == "range4" else None)
        if arm == NOISEOFF:
            assert config["sigma2_max"] == 0


@pytest.mark.parametrize("reused, source, arms", REUSED)
def test_a_reused_arm_is_its_source_seed_for_seed(reused, source, arms, archives):
    for arm in arms:
        for column in ("SR", "SPL"):
            now, before = (report.values(archives.results(a, arm), column) for a in (reused, source))
            assert list(now) == list(before), (reused, arm, column)


def test_the_selected_updates_the_prose_quotes(archives):
    """ "Every arm at 3000 updates selected its last or next-to-last checkpoint" (the
    summary), and every seed of the range-4 arms its last ("Every seed of both arms
    selected its last model", "Every seed again selected its last model")."""
    for archive, (methods, _) in SWEEPS.items():
        for arm in methods:
            assert {r["selected_update"] for r in archives.results(archive, arm)} <= {2500, 3000}, (archive, arm)
    for archive in ("ceiling_range4.tar.xz", "ceiling_range4_noiseoff.tar.xz"):
        for arm in SWEEPS[archive][0]:
            assert {r["selected_update"] for r in archives.results(archive, arm)} == {3000}


def test_the_noise_variance_the_prose_quotes(archives):
    """Eq. 7's variance at the end of training: "ends near 0.38" in today's rooms, "0.385 at
    the end of training here" at range 4 (the oracle's last chunk, mean over seeds)."""
    savn = report.values(archives.results("ceiling_savn.tar.xz", ORACLE), "charts/noise_variance")
    range4 = report.values(archives.results("ceiling_range4.tar.xz", ORACLE), "charts/noise_variance")
    doc = flat()
    assert f"{savn.mean():.2f}" == "0.38" and "whose variance ends near 0.38" in doc
    assert f"({range4.mean():.3f} at the end of training here)" in doc


def probe(name: str) -> dict:
    return json.loads((study_data.DATA / name).read_text())["methods"]


def first_fifth(seeds: list[dict]) -> list[int]:
    """Each seed's share (%) of successful episodes whose sub-goal t* falls in their first fifth."""
    return [round(100 * r["items"]["subgoal"]["shares"][0]) for r in seeds]


def test_the_probes_ran_their_conditions_on_seeds_0_to_4():
    savn = probe("ceiling_probe_savn.json")
    assert list(savn) == [ORACLE]
    assert [r["seed"] for r in savn[ORACLE]] == [0, 1, 2, 3, 4]
    assert set(savn[ORACLE][0]["sr"]) == {"trained", "noise off", "shuffled", "shuffled, noise off"}  # no f_w's
    range4 = probe("ceiling_probe_range4.json")
    assert list(range4) == [ORACLE, NOISEOFF]
    for seeds in range4.values():
        assert [r["seed"] for r in seeds] == [0, 1, 2, 3, 4]
    # the noise-off arm has no noise to switch off: its "noise off" condition is its trained one
    assert [r["sr"]["noise off"] for r in range4[NOISEOFF]] == [r["sr"]["trained"] for r in range4[NOISEOFF]]
    # the prose's shares of early sub-goals
    shares = first_fifth(savn[ORACLE])
    assert f"in {min(shares)}-{max(shares)}% of episodes (the oracle run's own probe)" in flat()
    shares = first_fifth(range4[ORACLE]) + first_fifth(range4[NOISEOFF])
    assert f"in {min(shares)}-{max(shares)}% of episodes (the probe's 40 training windows)" in flat()
