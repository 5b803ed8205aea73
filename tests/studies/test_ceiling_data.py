"""docs/ceiling.md's numbers are what its archived study computes (docs/data/ceiling_savn.tar.xz:
the oracle arm and the reused critic and ForeSIT arms, without checkpoints)."""

from pathlib import Path

import pytest
import study_data

from experiments import compare
from experiments import rundir
from experiments.reporting import report, stats

REPO = Path(__file__).resolve().parents[2]


def arm_row(results: dict, arm: str, label: str) -> str:
    """The docs' row of one arm: SR per seed, SR and SPL as mean ± std."""
    sr, spl = (report.values(results[arm], c) for c in ("SR", "SPL"))
    return (
        f"| {label} | {' / '.join(f'{x:.1f}' for x in sr)} | {sr.mean():.1f} ± {sr.std(ddof=1):.1f} | "
        f"{spl.mean():.1f} ± {spl.std(ddof=1):.1f} |"
    )


CRITIC, FORESIT, ORACLE = (
    "a3c+critic@learning_rate=3e-4",
    "a3c+foresit@learning_rate=3e-4",
    "a3c+oracle@learning_rate=3e-4",
)


@pytest.mark.parametrize("archive", ["ceiling_savn.tar.xz", "ceiling_priors.tar.xz"])
def test_ceiling_md_quotes_the_ceiling(tmp_path, capsys, archive):
    root = study_data.unpack(archive, tmp_path, (CRITIC, FORESIT, ORACLE))
    out = compare.main(
        compare.Args(
            run=root, pairs=(f"{CRITIC}:{ORACLE}", f"{CRITIC}:{FORESIT}"), ceiling=(f"{CRITIC}:{FORESIT}:{ORACLE}",)
        )
    )
    capsys.readouterr()
    doc = (REPO / "docs" / "ceiling.md").read_text()
    results = rundir.sweep_results(root)
    for arm, label in ((CRITIC, "a3c+critic"), (FORESIT, "a3c+foresit"), (ORACLE, "a3c+oracle (privileged)")):
        assert arm_row(results, arm, label) in doc, arm_row(results, arm, label)
    for (a, b), label in (
        ((CRITIC, ORACLE), "the ceiling: a3c+oracle (privileged) - a3c+critic"),
        ((CRITIC, FORESIT), "a3c+foresit - a3c+critic"),
    ):
        pair = out["pairs"][f"{b} - {a}"]
        row = (
            f"| {label} | {study_data.interval(pair['SR'])} | {study_data.interval(pair['SPL'])} | "
            f"{pair['robust']['SR']['mde']:.1f} |"
        )
        assert row in doc, row
    ceiling = out["ceiling"][f"{ORACLE} - {CRITIC}"]
    sr = stats.paired(report.values(results[CRITIC], "SR"), report.values(results[ORACLE], "SR"))
    flat = " ".join(doc.split())
    assert not ceiling["SPL"]["resolved"]
    if archive == "ceiling_savn.tar.xz":
        assert not ceiling["SR"]["resolved"] and "ceiling not resolved" in doc
        assert f"moves test SR by {study_data.interval(sr)} points over the critic alone" in flat
    else:
        share = ceiling["SR"]
        assert share["resolved"]
        assert f"helps by {study_data.interval(sr)} SR over the critic alone" in flat
        assert f"{share['share']:.2f} [{share['share_low']:.2f}, {share['share_high']:.2f}]" in flat


def test_ceiling_md_quotes_the_probe_of_the_oracle():
    import json

    seeds = json.loads((study_data.DATA / "ceiling_probe_savn.json").read_text())["methods"][ORACLE]
    assert [r["seed"] for r in seeds] == [0, 1, 2, 3, 4]
    trained = [r["sr"]["trained"] for r in seeds]
    assert set(seeds[0]["sr"]) == {"trained", "noise off", "shuffled", "shuffled, noise off"}  # no f_w conditions
    doc = (REPO / "docs" / "ceiling.md").read_text()
    for condition, label in (
        ("noise off", "noise off"),
        ("shuffled", "shuffled (another episode's goal view)"),
        ("shuffled, noise off", "shuffled, noise off"),
    ):
        values = [r["sr"][condition] for r in seeds]
        s = stats.summary(values)
        row = f"| {label} | {s['mean']:.1f} ± {s['std']:.1f} | {study_data.interval(stats.paired(trained, values))} |"
        assert row in doc, row
    s = stats.summary(trained)
    assert f"| trained | {s['mean']:.1f} ± {s['std']:.1f} | |" in doc


def test_ceiling_md_quotes_the_noise_off_oracle(tmp_path, capsys):
    """The noise-off oracle (docs/data/ceiling_savn_noiseoff.tar.xz): its row, its ceiling over
    the critic (not resolved) and its pair with the noisy oracle, and results.md's table of
    why part 3 was not run."""
    noiseoff = "a3c+oracle@learning_rate=3e-4,sigma2_max=0"
    root = study_data.unpack("ceiling_savn_noiseoff.tar.xz", tmp_path, (CRITIC, FORESIT, ORACLE, noiseoff))
    out = compare.main(
        compare.Args(
            run=root,
            pairs=(f"{CRITIC}:{noiseoff}", f"{ORACLE}:{noiseoff}"),
            ceiling=(f"{CRITIC}:{FORESIT}:{noiseoff}",),
        )
    )
    capsys.readouterr()
    doc = (REPO / "docs" / "ceiling.md").read_text()
    results = rundir.sweep_results(root)
    row = arm_row(results, noiseoff, "a3c+oracle@sigma2_max=0 (privileged)")
    assert row in doc, row
    for a, label in (
        (CRITIC, "the noise-off ceiling: a3c+oracle@sigma2_max=0 - a3c+critic"),
        (ORACLE, "a3c+oracle@sigma2_max=0 - a3c+oracle (both privileged)"),
    ):
        pair = out["pairs"][f"{noiseoff} - {a}"]
        row = (
            f"| {label} | {study_data.interval(pair['SR'])} | {study_data.interval(pair['SPL'])} | "
            f"{pair['robust']['SR']['mde']:.1f} |"
        )
        assert row in doc, row
    ceiling = out["ceiling"][f"{noiseoff} - {CRITIC}"]["SR"]
    assert not ceiling["resolved"]
    pair = out["pairs"][f"{noiseoff} - {CRITIC}"]
    results_md = (REPO / "docs" / "results.md").read_text()
    assert (
        f"| today's rooms, the oracle without noise (`sigma2_max=0`) | {study_data.interval(pair['SR'])} | "
        f"{pair['robust']['SR']['mde']:.1f} |"
    ) in results_md
    assert "| today's rooms, the oracle with Eq. 7's noise | +1.4 [-2.0, +4.7] | 4.5 |" in results_md
    assert "| rooms with priors, the oracle with Eq. 7's noise | +4.1 [+0.2, +8.0] | 5.3 |" in results_md


NOISEOFF = "a3c+oracle@learning_rate=3e-4,sigma2_max=0"


@pytest.mark.parametrize(
    "archive, methods, label, rows",
    [
        (
            "ceiling_savn_epyc.tar.xz",
            (CRITIC, ORACLE, NOISEOFF),
            "a3c+critic, on the EPYC",
            (
                (
                    ORACLE,
                    "the ceiling: a3c+oracle (privileged) - a3c+critic",
                    "today's rooms, machine-matched (the critic retrained on the EPYC), with the noise",
                ),
                (
                    NOISEOFF,
                    "the noise-off ceiling: a3c+oracle@sigma2_max=0 - a3c+critic",
                    "today's rooms, machine-matched, without noise",
                ),
            ),
        ),
        (
            "ceiling_priors_epyc.tar.xz",
            (CRITIC, ORACLE),
            "a3c+critic, on the EPYC, rooms with priors",
            (
                (
                    ORACLE,
                    "the ceiling in rooms with priors: a3c+oracle (privileged) - a3c+critic",
                    "rooms with priors, machine-matched (the critic retrained on the EPYC), with the noise",
                ),
            ),
        ),
        (
            "ceiling_priors_noiseoff.tar.xz",
            (CRITIC, ORACLE, NOISEOFF),
            "a3c+critic, on the EPYC, rooms with priors",
            (
                (
                    NOISEOFF,
                    "the noise-off ceiling in rooms with priors: a3c+oracle@sigma2_max=0 - a3c+critic",
                    "rooms with priors, machine-matched, without noise",
                ),
            ),
        ),
    ],
)
def test_ceiling_md_quotes_the_machine_matched_ceilings(tmp_path, capsys, archive, methods, label, rows):
    """The critic retrained on the oracles' machine (docs/data/`archive`): its row, each
    ceiling (none resolved), results.md's rows and the README's sentence."""
    root = study_data.unpack(archive, tmp_path, methods)
    out = compare.main(compare.Args(run=root, pairs=tuple(f"{CRITIC}:{arm}" for arm, _, _ in rows)))
    capsys.readouterr()
    doc = (REPO / "docs" / "ceiling.md").read_text()
    results = rundir.sweep_results(root)
    assert arm_row(results, CRITIC, label) in doc, arm_row(results, CRITIC, label)
    results_md = (REPO / "docs" / "results.md").read_text()
    for arm, pair_label, setting in rows:
        pair = out["pairs"][f"{arm} - {CRITIC}"]
        assert pair["SR"]["ci_low"] < 0 < pair["SR"]["ci_high"]  # not resolved
        mde = f"{pair['robust']['SR']['mde']:.1f}"
        row = f"| {pair_label} | {study_data.interval(pair['SR'])} | {study_data.interval(pair['SPL'])} | {mde} |"
        assert row in doc, row
        assert f"| {setting} | {study_data.interval(pair['SR'])} | {mde} |" in results_md
    ceiling = study_data.interval(stats.paired(*(report.values(results[arm], "SR") for arm in (CRITIC, ORACLE))))
    flat = " ".join(doc.split())
    if "priors" in archive:
        assert f"the ceiling becomes {ceiling}" in flat


def test_ceiling_md_quotes_the_ceiling_at_range_4(tmp_path, capsys):
    """The candidate family (rooms with priors, perception range 4; docs/data/ceiling_range4.tar.xz,
    trained with the range): both arms' rows, the ceiling resolved below 0 where the docs say
    the oracle costs, results.md's row and the README's sentence."""
    root = study_data.unpack("ceiling_range4.tar.xz", tmp_path, (CRITIC, ORACLE))
    results = rundir.sweep_results(root)
    for arm in (CRITIC, ORACLE):
        config = rundir.read_json(root / "methods" / arm / "run.json")["config"]
        assert config["priors"] is True and config["perception_range"] == 4.0
    out = compare.main(compare.Args(run=root, pairs=(f"{CRITIC}:{ORACLE}",)))
    capsys.readouterr()
    doc = (REPO / "docs" / "ceiling.md").read_text()
    for arm, label in (
        (CRITIC, "a3c+critic, on the EPYC, rooms with priors, range 4"),
        (ORACLE, "a3c+oracle (privileged), on the EPYC, rooms with priors, range 4"),
    ):
        assert arm_row(results, arm, label) in doc, arm_row(results, arm, label)
    pair = out["pairs"][f"{ORACLE} - {CRITIC}"]
    assert pair["SR"]["ci_high"] < 0  # resolved, below 0: "the oracle costs"
    mde = f"{pair['robust']['SR']['mde']:.1f}"
    sr = study_data.interval(pair["SR"])
    row = f"| the ceiling at range 4: a3c+oracle (privileged) - a3c+critic | {sr} | {study_data.interval(pair['SPL'])} | {mde} |"
    assert row in doc, row
    assert f"**Here the oracle costs**: {sr} SR" in doc
    assert (
        f"| rooms with priors, range 4, machine-matched, with the noise | {sr} | {mde} |"
        in (REPO / "docs" / "results.md").read_text()
    )


def test_ceiling_md_quotes_the_noise_off_ceiling_at_range_4(tmp_path, capsys):
    """The noise-off oracle in the candidate family (docs/data/ceiling_range4_noiseoff.tar.xz,
    the critic and the noisy oracle reused, so machine-matched): its row, both pairs (neither
    resolved, as the docs say "cannot tell"), results.md's row and the README's clause."""
    root = study_data.unpack("ceiling_range4_noiseoff.tar.xz", tmp_path, (CRITIC, ORACLE, NOISEOFF))
    results = rundir.sweep_results(root)
    for arm in (CRITIC, ORACLE, NOISEOFF):
        config = rundir.read_json(root / "methods" / arm / "run.json")["config"]
        assert config["priors"] is True and config["perception_range"] == 4.0
    # the reused arms are the noisy study's, seed for seed
    noisy = rundir.sweep_results(study_data.unpack("ceiling_range4.tar.xz", tmp_path / "noisy", (CRITIC, ORACLE)))
    for arm in (CRITIC, ORACLE):
        assert list(report.values(results[arm], "SR")) == list(report.values(noisy[arm], "SR"))
    out = compare.main(compare.Args(run=root, pairs=(f"{CRITIC}:{NOISEOFF}", f"{ORACLE}:{NOISEOFF}")))
    capsys.readouterr()
    doc = (REPO / "docs" / "ceiling.md").read_text()
    label = "a3c+oracle@sigma2_max=0 (privileged), on the EPYC, rooms with priors, range 4"
    assert arm_row(results, NOISEOFF, label) in doc, arm_row(results, NOISEOFF, label)
    for a, pair_label in (
        (CRITIC, "the noise-off ceiling at range 4: a3c+oracle@sigma2_max=0 - a3c+critic"),
        (ORACLE, "a3c+oracle@sigma2_max=0 - a3c+oracle at range 4 (both privileged)"),
    ):
        pair = out["pairs"][f"{NOISEOFF} - {a}"]
        assert pair["SR"]["ci_low"] < 0 < pair["SR"]["ci_high"]  # not resolved
        mde = f"{pair['robust']['SR']['mde']:.1f}"
        row = f"| {pair_label} | {study_data.interval(pair['SR'])} | {study_data.interval(pair['SPL'])} | {mde} |"
        assert row in doc, row
    pair = out["pairs"][f"{NOISEOFF} - {CRITIC}"]
    sr, mde = study_data.interval(pair["SR"]), f"{pair['robust']['SR']['mde']:.1f}"
    assert (
        f"| rooms with priors, range 4, machine-matched, without noise | {sr} | {mde} |"
        in (REPO / "docs" / "results.md").read_text()
    )
    assert "**Without the noise we cannot tell the ceiling from 0**, and its point estimate is the" in doc
    assert f"noisy arm's: {sr} SR over the critic alone (MDE {mde})" in " ".join(doc.split())
    # the noise's own effect, noise-off - noisy oracle, and its upper end (issue 81: once quoted
    # as the other pair's +0.7)
    noise = out["pairs"][f"{NOISEOFF} - {ORACLE}"]
    quote = (
        f"Taking Eq. 7's noise away moves the oracle by {study_data.interval(noise['SR'])} SR "
        f"(MDE {noise['robust']['SR']['mde']:.1f}), an interval whose upper end is {study_data.signed(noise['SR']['ci_high'])}."
    )
    assert quote in " ".join(doc.split()), quote


def test_ceiling_md_quotes_the_probe_at_range_4():
    """docs/data/ceiling_probe_range4.json: each oracle arm's probe rows, and the noise-off
    arm's shuffled condition resolved below 0 where the docs say that policy reads the goal view."""
    import json

    methods = json.loads((study_data.DATA / "ceiling_probe_range4.json").read_text())["methods"]
    doc = (REPO / "docs" / "ceiling.md").read_text()
    labels = {
        "noise off": "noise off",
        "shuffled": "shuffled (another episode's goal view)",
        "shuffled, noise off": "shuffled, noise off",
    }
    for arm, name, conditions in (
        (ORACLE, "a3c+oracle (Eq. 7's noise)", ("noise off", "shuffled", "shuffled, noise off")),
        (NOISEOFF, "a3c+oracle@sigma2_max=0", ("shuffled",)),
    ):
        seeds = methods[arm]
        assert [r["seed"] for r in seeds] == [0, 1, 2, 3, 4]
        trained = [r["sr"]["trained"] for r in seeds]
        s = stats.summary(trained)
        assert f"| {name} | trained | {s['mean']:.1f} ± {s['std']:.1f} | |" in doc
        for condition in conditions:
            values = [r["sr"][condition] for r in seeds]
            s, pair = stats.summary(values), stats.paired(trained, values)
            row = f"| {name} | {labels[condition]} | {s['mean']:.1f} ± {s['std']:.1f} | {study_data.interval(pair)} |"
            assert row in doc, row
            if arm == NOISEOFF:
                assert pair["ci_high"] < 0
                assert f"latent lowers its SR by {study_data.interval(pair)}" in " ".join(doc.split())
    # the noise-off arm has no noise to switch off: its "noise off" condition is its trained one
    assert [r["sr"]["noise off"] for r in methods[NOISEOFF]] == [r["sr"]["trained"] for r in methods[NOISEOFF]]


def test_ceiling_md_quotes_the_range_4_arms_along_training(tmp_path):
    """The validation table of "Along training" (docs/data/ceiling_range4_noiseoff.tar.xz): the
    critic's validation SR at each checkpoint and each oracle arm's paired difference, and the
    last checkpoint unresolved where the docs say validation cannot tell."""
    import numpy as np

    root = study_data.unpack("ceiling_range4_noiseoff.tar.xz", tmp_path, (CRITIC, ORACLE, NOISEOFF))
    curves = {}
    for arm in (CRITIC, ORACLE, NOISEOFF):
        seeds = rundir.read_json(root / "methods" / arm / "results.json")["results"]
        assert [r["seed"] for r in seeds] == [0, 1, 2, 3, 4]
        updates = [[v["update"] for v in r["validation"]] for r in seeds]
        assert all(u == [500, 1000, 1500, 2000, 2500, 3000] for u in updates)
        curves[arm] = np.array([[v["SR"] for v in r["validation"]] for r in seeds])
    doc = (REPO / "docs" / "ceiling.md").read_text()
    above = {arm: 0 for arm in (ORACLE, NOISEOFF)}
    for i, update in enumerate(range(500, 3001, 500)):
        critic = curves[CRITIC][:, i]
        pairs = [stats.paired(critic, curves[arm][:, i]) for arm in (ORACLE, NOISEOFF)]
        row = (
            f"| {update} | {critic.mean():.1f} ± {critic.std(ddof=1):.1f} | "
            + " | ".join(study_data.interval(p) for p in pairs)
            + " |"
        )
        assert row in doc, row
        assert all(p["ci_high"] > 0 for p in pairs)  # "no oracle arm is behind the critic at any checkpoint"
        if update == 3000:
            assert all(p["ci_low"] < 0 for p in pairs)  # cannot tell at the selected model
        for arm, p in zip((ORACLE, NOISEOFF), pairs):
            above[arm] += p["ci_low"] > 0
    assert above == {ORACLE: 0, NOISEOFF: 2}  # "the noise-off arm's interval lies above 0 at two of the six"


def test_ceiling_md_quotes_the_machine_shift_of_the_critic():
    """The critic trained on the EPYC against the Xeon's, the same seeds and program (each
    family's two archives, read in place): ceiling.md's EPYC - Xeon intervals, judged by
    experiments.reporting.verdicts (issue 81: once worded "the machine moved each seed, not
    the mean" with no interval)."""
    from experiments.reporting.registry import Archives
    from experiments.reporting.verdicts import verdict

    archives = Archives(study_data.DATA)
    flat = " ".join((REPO / "docs" / "ceiling.md").read_text().split())
    for epyc, xeon, words in (
        ("ceiling_savn_epyc.tar.xz", "ceiling_savn.tar.xz", "EPYC - Xeon is {} SR (MDE {:.1f}), and each seed moved"),
        ("ceiling_priors_epyc.tar.xz", "ceiling_priors.tar.xz", "EPYC - Xeon is {} SR for the critic (not resolved)"),
    ):
        a, b = archives.results(xeon, CRITIC), archives.results(epyc, CRITIC)
        assert [r["seed"] for r in a] == [r["seed"] for r in b] == [0, 1, 2, 3, 4]
        v = verdict(report.values(b, "SR") - report.values(a, "SR"), "SR", 3.8)
        assert v.word == "cannot tell"
        quote = words.format(v.figures(), v.mde)
        assert quote in flat, quote
