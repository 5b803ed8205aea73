"""The fairness study (issue 44: a3c, a3c+critic and a3c+foresit at Adam 3e-4 and 1e-3,
seeds 0-4, quick; ORG's three arms likewise on org; the 3e-4 arms at 3x the budget): the
figures docs/results.md and the README quote are those of its files, kept without checkpoints
as docs/data/fair_lr3e-4.tar.xz, fair_tune.tar.xz, fair_tune_org.tar.xz, fair_3x.tar.xz and
others, recomputed here by
`experiments.compare` and `experiments.tune`, as results.md's commands make them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import study_data

from experiments import compare, rundir
from experiments.reporting import report, stats

REPO = Path(__file__).resolve().parents[2]
ARMS = {
    "a3c": "a3c@learning_rate=3e-4",
    "a3c+foresit": "a3c+foresit@learning_rate=3e-4",
    "a3c+critic": "a3c+critic@learning_rate=3e-4",
}  # (the sweep's order)
PAIRS = (("a3c", "a3c+foresit"), ("a3c", "a3c+critic"), ("a3c+critic", "a3c+foresit"))


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """(per-arm results, experiments.compare's output for results.md's pairs)."""
    root = study_data.unpack("fair_lr3e-4.tar.xz", tmp_path_factory.mktemp("fair"), ARMS.values())
    out = compare.main(compare.Args(run=root, pairs=tuple(f"{ARMS[a]}:{ARMS[b]}" for a, b in PAIRS)))
    loaded = rundir.sweep_results(root)
    return {short: loaded[name] for short, name in ARMS.items()}, out["pairs"]


def signed(x: float) -> str:
    return f"{x:+.1f}".replace("+-", "-")


def interval(p: dict) -> str:
    return f"{signed(p['diff'])} [{signed(p['ci_low'])}, {signed(p['ci_high'])}]"


def test_results_md_quotes_the_sweep(study):
    arms, pairs = study
    results = (REPO / "docs" / "results.md").read_text()
    for arm, per_seed in arms.items():
        assert [r["seed"] for r in per_seed] == [0, 1, 2, 3, 4]
        sr, spl = report.values(per_seed, "SR"), report.values(per_seed, "SPL")
        s, iqm = stats.summary(sr), stats.stratified_bootstrap_ci(stats.iqm, sr)
        row = (
            f"| {arm} | " + " / ".join(f"{x:.1f}" for x in sr) + f" | {s['mean']:.1f} ± {s['std']:.1f} | "
            f"{spl.mean():.1f} ± {spl.std(ddof=1):.1f} | {iqm[0]:.1f} [{iqm[1]:.1f}, {iqm[2]:.1f}] |"
        )
        assert row in results, row
    for a, b in PAIRS:
        pair = pairs[f"{ARMS[b]} - {ARMS[a]}"]
        robust = pair["robust"]["SR"]
        poi = robust["probability_of_improvement"]
        row = (
            f"| {b} - {a} | {interval(pair['SR'])} | {interval(pair['SPL'])} | "
            f"{poi[0]:.2f} [{poi[1]:.2f}, {poi[2]:.2f}] | {robust['p_holm']:.3f} | {robust['mde']:.1f} |"
        )
        assert row in results, row


def test_the_base_is_ahead_on_every_seed_as_results_md_says(study):
    arms, _ = study
    gaps = report.values(arms["a3c"], "SR") - report.values(arms["a3c+foresit"], "SR")
    assert (gaps > 0).all()
    assert f"by {gaps.min():.1f} to {gaps.max():.1f} points" in (REPO / "docs" / "results.md").read_text()


def test_results_md_quotes_the_probe_of_the_3e4_foresit_seeds():
    """The f_w baselines and the replayed fit options of results.md are those of
    docs/data/fair_probe_lr3e-4.json (what `experiments.probe --fit-options` wrote)."""
    import json

    from experiments.reporting import probing

    report = json.loads((REPO / "docs" / "data" / "fair_probe_lr3e-4.json").read_text())
    results = (REPO / "docs" / "results.md").read_text()
    per_seed = report["methods"]["a3c+foresit@learning_rate=3e-4"]
    assert [r["seed"] for r in per_seed] == [0, 1, 2, 3, 4] and report["fit_passes"] == 5
    for r in per_seed:
        row = study_data.probe_fit_row(r)
        assert row in results, row
        options = r["items"]["fit_options"]
        assert list(options) == list(probing.FIT_OPTIONS)
        row = f"| {r['seed']} | " + " | ".join(f"{v:.2f}" for v in options.values()) + " |"
        assert row in results, row


def test_results_md_quotes_the_kept_optimizer_state_against_a_fresh_one():
    """The "state kept" bullet's paired differences are those of the probe's data."""
    import json

    report = json.loads((REPO / "docs" / "data" / "fair_probe_lr3e-4.json").read_text())
    options = [r["items"]["fit_options"] for r in report["methods"]["a3c+foresit@learning_rate=3e-4"]]
    results = " ".join((REPO / "docs" / "results.md").read_text().split())
    for kept, fresh, text in (
        ("state kept", "as trained", "{:+.3f} R^2 against a fresh state at each flush (per seed {:+.3f} to {:+.3f})"),
        ("state kept, lr 3e-4", "lr 3e-4", "{:+.3f} with lr 3e-4 ({:+.3f} to {:+.3f})"),
    ):
        d = np.array([o[kept] - o[fresh] for o in options])
        quoted = text.format(d.mean(), d.min(), d.max())
        assert quoted in results, quoted


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_the_gpu_script_runs_dry_on_a_cpu(tmp_path):
    """scripts/fair_study_gpu.sh at a tiny size: the three arms side by side at 3e-4, their
    table and pairs, the 1e-4 arms until their deadline, one archive without checkpoints."""
    import os
    import subprocess
    import tarfile

    env = {
        **os.environ,
        "PRESET": "tiny",
        "SEEDS": "2",
        "UPDATES": "4",
        "LOW_LR_SECONDS": "120",
        "OUT": str(tmp_path / "out"),
        "RUNS": str(tmp_path / "runs"),
    }
    proc = subprocess.run(
        ["bash", str(REPO / "scripts" / "fair_study_gpu.sh")], env=env, capture_output=True, text=True, cwd=tmp_path
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    runs_ = tmp_path / "runs"
    assert (runs_ / "lr3e-4_3x" / "table1.md").is_file()
    assert "a3c+foresit@learning_rate=3e-4 - a3c@learning_rate=3e-4" in (runs_ / "lr3e-4_3x" / "compare.md").read_text()
    with tarfile.open(tmp_path / "out" / "fair_gpu.tar.xz") as tar:
        names = tar.getnames()
    assert any(n.endswith("lr3e-4_3x/table1.md") for n in names) and not any("checkpoints" in n for n in names)


def test_results_md_quotes_the_tuned_comparison(tmp_path):
    """The tuned study's grid and best-vs-best rows in results.md are what `experiments.tune`'s
    report computes from its files (docs/data/fair_tune.tar.xz: the tune folder, no checkpoints)."""
    tuned = study_data.tune_report("fair_tune.tar.xz", tmp_path)
    assert tuned["chosen"] == {
        "a3c": "learning_rate=1e-3",
        "a3c+critic": "learning_rate=3e-4",
        "a3c+foresit": "learning_rate=3e-4",
    }
    doc = (REPO / "docs" / "results.md").read_text()
    for row in tuned["grid_rows"]:
        assert study_data.grid_line(row) in doc, study_data.grid_line(row)
    best_vs_best = tuned["best_vs_best"]
    for name, pair in best_vs_best.items():
        assert study_data.best_vs_best_line(name, pair) in doc, study_data.best_vs_best_line(name, pair)
    headline = best_vs_best["a3c+foresit - a3c"]
    summary = " ".join(doc.split())  # results.md's "In brief" (once the README's Results)
    iqm = headline["robust"]["SR"]
    for quoted in (
        f"{interval(headline['SR'])} SR and {interval(headline['SPL'])} SPL",
        f"IQM of SR is {iqm['iqm_b'][0]:.1f} against {iqm['iqm_a'][0]:.1f}",
        f"a3c+foresit - a3c+critic is {interval(best_vs_best['a3c+foresit - a3c+critic']['SR'])} SR",
    ):
        assert quoted in summary, quoted
    assert headline["SR"]["ci_low"] < 0 < headline["SR"]["ci_high"] and headline["SPL"]["ci_high"] < 0  # the words


def test_results_md_quotes_the_bases_with_savns_head_and_one_step_td(tmp_path, capsys):
    root = study_data.unpack("fair_bases.tar.xz", tmp_path, ("a3c", "a3c@value_head=linear", "a3c@gae_lambda=0"))
    arms = ("a3c@value_head=linear", "a3c@gae_lambda=0")
    out = compare.main(compare.Args(run=root, pairs=tuple(f"a3c:{b}" for b in arms)))
    capsys.readouterr()
    results, doc = rundir.sweep_results(root), (REPO / "docs" / "results.md").read_text()
    for b in arms:
        row = study_data.pair_row(out, results, "a3c", b)
        assert row in doc, row


def test_results_md_quotes_the_better_fitted_fw_arm(tmp_path, capsys):
    arm = "a3c+foresit@imagination_lr=3e-4"
    root = study_data.unpack("fair_fw.tar.xz", tmp_path, ("a3c", "a3c+critic", "a3c+foresit", arm))
    bases = ("a3c+foresit", "a3c", "a3c+critic")
    out = compare.main(compare.Args(run=root, pairs=tuple(f"{a}:{arm}" for a in bases)))
    capsys.readouterr()
    results, doc = rundir.sweep_results(root), (REPO / "docs" / "results.md").read_text()
    for a in bases:
        row = study_data.pair_row(out, results, a, arm)
        assert row in doc, row
    assert out["pairs"][f"{arm} - a3c"]["robust"]["SPL"]["p_holm"] < 0.05  # "with an interval that excludes 0"


def test_results_md_quotes_the_org_tune(tmp_path):
    """The org tune's grid and best-vs-best rows in results.md are what `experiments.tune`'s
    report computes from its files (docs/data/fair_tune_org.tar.xz: the tune folder, no checkpoints)."""
    tuned = study_data.tune_report("fair_tune_org.tar.xz", tmp_path)
    assert tuned["chosen"] == {m: "learning_rate=1e-3" for m in ("a3c+org", "a3c+org+critic", "a3c+org+foresit")}
    doc = (REPO / "docs" / "results.md").read_text()
    for row in tuned["grid_rows"]:
        assert study_data.grid_line(row) in doc, study_data.grid_line(row)
    for name, pair in tuned["best_vs_best"].items():
        assert study_data.best_vs_best_line(name, pair) in doc, study_data.best_vs_best_line(name, pair)
    # "The same numbers on two machines": every 1e-3 seed's test SR is docs/mechanism.md's (the EPYC's).
    mechanism = (REPO / "docs" / "mechanism.md").read_text()
    for method, by_point in tuned["table"].items():
        per_seed = [r["selected"]["overall"]["SR"] for r in tuned["results"][by_point["learning_rate=1e-3"]]]
        joined = " / ".join(f"{x:.1f}" for x in per_seed)
        assert f"| {method} | {joined} |" in mechanism and joined in " ".join(doc.split()), joined


def test_results_md_quotes_the_noise_placement_arm_and_its_probe(tmp_path, capsys):
    """results.md's rows for Algorithm 1's noise placement are what experiments.compare
    computes from docs/data/fair_noise.tar.xz, and its probe quotes are
    docs/data/fair_probe_noise.json's (beside Eq. 6's, fair_probe_lr3e-4.json)."""
    import json

    from experiments.reporting import stats

    arm = "a3c+foresit@learning_rate=3e-4,imagination_noise=input"
    bases = ("a3c+foresit@learning_rate=3e-4", "a3c+critic@learning_rate=3e-4", "a3c")
    root = study_data.unpack("fair_noise.tar.xz", tmp_path, ("a3c", bases[1], bases[0], arm))
    out = compare.main(compare.Args(run=root, pairs=tuple(f"{a}:{arm}" for a in bases)))
    capsys.readouterr()
    results, doc = rundir.sweep_results(root), (REPO / "docs" / "results.md").read_text()
    flat = " ".join(doc.split())
    for a in bases:
        row = study_data.pair_row(out, results, a, arm)
        assert row in doc, row
    vs_base = out["pairs"][f"{arm} - a3c"]
    assert vs_base["robust"]["SPL"]["p_holm"] < 0.01 and vs_base["robust"]["SPL"]["probability_of_improvement"][0] == 0
    assert f"by {-vs_base['SPL']['diff']:.1f} SPL on every seed" in flat

    def shifts(data: str, method: str) -> dict:
        seeds = json.loads((study_data.DATA / data).read_text())["methods"][method]
        trained = [r["sr"]["trained"] for r in seeds]
        return {
            c: study_data.interval(stats.paired(trained, [r["sr"][c] for r in seeds]))
            for c in ("shuffled, noise off", "untrained f_w")
        }

    mine, eq6 = shifts("fair_probe_noise.json", arm), shifts("fair_probe_lr3e-4.json", bases[0])
    assert (
        f"noise off costs {mine['shuffled, noise off']} SR (Eq. 6's placement: {eq6['shuffled, noise off']}), "
        f"an untrained f_w {mine['untrained f_w']} (Eq. 6's: {eq6['untrained f_w']})"
    ) in flat
    # results.md's "In brief" (once the README's Results)
    assert (
        f"noise inside f_w's input ({study_data.interval(out['pairs'][f'{arm} - {bases[0]}']['SR'])} SR over Eq. 6's)"
        in flat
    )


def _three_x_rows(tmp_path) -> tuple[list[str], dict]:
    """results.md's rows of the 3x study (docs/data/fair_3x.tar.xz: the 3e-4 sweep extended to
    9000 updates, each arm's 3000-update results kept beside): per arm, 3000 against 9000
    updates on the same seeds; the pairs at 9000 as experiments.compare computes them; each
    pair's gap at 3000, at 9000 and its change, seed by seed. Also returns the per-arm results."""
    import json

    root = study_data.unpack("fair_3x.tar.xz", tmp_path, ARMS.values())
    out = compare.main(compare.Args(run=root, pairs=tuple(f"{ARMS[a]}:{ARMS[b]}" for a, b in PAIRS)))
    results_9000 = rundir.sweep_results(root)
    at = {
        3000: {
            short: json.loads((root / "methods" / arm / "results_3000_updates.json").read_text())["results"]
            for short, arm in ARMS.items()
        },
        9000: {short: results_9000[arm] for short, arm in ARMS.items()},
    }
    values = {
        n: {a: {m: report.values(r, m) for m in ("SR", "SPL")} for a, r in arms.items()} for n, arms in at.items()
    }

    def mean_std(v) -> str:
        return f"{v.mean():.1f} ± {v.std(ddof=1):.1f}"

    rows = []
    for a in ("a3c", "a3c+critic", "a3c+foresit"):
        cells = []
        for m in ("SR", "SPL"):
            before, after = values[3000][a][m], values[9000][a][m]
            cells += [mean_std(before), mean_std(after), study_data.interval(stats.paired(before, after))]
        updates = " / ".join(str(r["selected_update"]) for r in at[9000][a])
        rows.append(f"| {a} | " + " | ".join(cells) + f" | {updates} |")
    rows += [study_data.pair_row(out, results_9000, ARMS[a], ARMS[b]) for a, b in PAIRS]
    for a, b in PAIRS:
        cells = []
        for m in ("SR", "SPL"):
            gaps = {n: values[n][b][m] - values[n][a][m] for n in (3000, 9000)}
            cells += [study_data.interval(stats.paired(values[n][a][m], values[n][b][m])) for n in (3000, 9000)]
            cells.append(study_data.interval(stats.paired(gaps[3000], gaps[9000])))
        rows.append(f"| {b} - {a} | " + " | ".join(cells) + " |")
    return rows, {"at": at, "root": root, "out": out}


def test_results_md_quotes_the_3x_study(tmp_path, capsys):
    """The 3x study's rows in results.md and the README's clause are what its files compute,
    and the extension is the first sweep's runs continued: each arm's 3000-update results are
    fair_lr3e-4.tar.xz's, and its validation history begins with that sweep's."""
    import json

    rows, found = _three_x_rows(tmp_path / "3x")
    capsys.readouterr()
    doc = (REPO / "docs" / "results.md").read_text()
    for row in rows:
        assert row in doc, row
    first = study_data.unpack("fair_lr3e-4.tar.xz", tmp_path / "1x", ARMS.values())
    for short, arm in ARMS.items():
        assert found["at"][3000][short] == json.loads((first / "methods" / arm / "results.json").read_text())["results"]
        history = json.loads((found["root"] / "methods" / arm / "progress.json").read_text())["history"]
        history_3000 = json.loads((first / "methods" / arm / "progress.json").read_text())["history"]
        assert [h[:6] for h in history] == history_3000 and {len(h) for h in history} == {18}
    pair = found["out"]["pairs"][f"{ARMS['a3c+foresit']} - {ARMS['a3c']}"]
    mde = pair["robust"]["SR"]["mde"]
    assert pair["SR"]["ci_high"] < 3.8  # the paper's gain is outside the interval
    quote = f"a3c+foresit - a3c is {study_data.interval(pair['SR'])} SR (five seeds detect {mde:.1f} points here,"
    assert quote in " ".join(doc.split()), quote  # results.md's "In brief"


def test_results_md_quotes_a3cs_rate_at_3x(tmp_path):
    """At 9000 updates a3c's learning rate is chosen on validation (docs/data/fair_tune_3x.tar.xz:
    the tune report over the two extended sweeps): results.md's grid rows and the paired
    differences it quotes are what its files compute."""
    from experiments.reporting.tuning import selection_sr

    tuned = study_data.tune_report("fair_tune_3x.tar.xz", tmp_path)
    assert tuned["chosen"] == {"a3c": "learning_rate=3e-4"}
    doc = (REPO / "docs" / "results.md").read_text()
    for row in tuned["grid_rows"]:
        assert study_data.grid_line(row) in doc, study_data.grid_line(row)
    fast, slow = tuned["results"]["a3c@learning_rate=1e-3"], tuned["results"]["a3c@learning_rate=3e-4"]
    for arm in ("a3c@learning_rate=1e-3", "a3c@learning_rate=3e-4"):  # both trained 9000 updates
        assert rundir.read_json(tmp_path / "tune" / "sweep" / "methods" / arm / "results.json")["updates"] == 9000
    val = study_data.interval(stats.paired(selection_sr(fast), selection_sr(slow)))
    sr, spl = (study_data.interval(stats.paired(report.values(fast, m), report.values(slow, m))) for m in ("SR", "SPL"))
    flat = " ".join(doc.split())
    quote = f"3e-4 - 1e-3 is {val} in validation SR, {sr} in test SR and {spl} in test SPL"
    assert quote in flat, quote
    # "without seed 3 the two rates tie": each rate's mean validation SR of the selected models
    # over seeds 0, 1, 2 and 4, named by its rate (issue 81 found them quoted in the wrong order)
    tie = {
        rate: selection_sr([r for r in per_seed if r["seed"] != 3]).mean()
        for rate, per_seed in (("3e-4", slow), ("1e-3", fast))
    }
    quote = f"without seed 3 the two rates tie, {tie['3e-4']:.1f} at 3e-4 and {tie['1e-3']:.1f} at 1e-3"
    assert quote in flat, quote
    plan = " ".join((REPO / "docs" / "plans" / "replication_3x.md").read_text().split())
    assert f"3e-4 is {tie['3e-4']:.1f} and 1e-3 is {tie['1e-3']:.2f}" in plan  # the plan's dated correction
    # ForeSIT at 3e-4 against a3c at 1e-3, both at 9000 updates (the 3x sweep's ForeSIT), paired
    # by seed: the pair results.md and the README quote beside the exclusion of +3.8.
    foresit = rundir.sweep_results(study_data.unpack("fair_3x.tar.xz", tmp_path / "3x", ARMS.values()))[
        ARMS["a3c+foresit"]
    ]
    assert [r["seed"] for r in foresit] == [r["seed"] for r in fast] == [0, 1, 2, 3, 4]
    pair = stats.paired(report.values(fast, "SR"), report.values(foresit, "SR"))
    assert pair["ci_low"] < 3.8 < pair["ci_high"]  # "does not exclude the paper's +3.8"
    assert f"ForeSIT - a3c at 9000 updates is {study_data.interval(pair)}, which does not exclude it" in flat


def test_results_md_quotes_the_archived_replicate_of_its_first_table(tmp_path):
    """The first table of results.md's "In brief" (once the README's) has no archive; it quotes
    the same pair's archived replicate (the tune study's 1e-3 arms, docs/data/fair_tune.tar.xz)
    beside it."""
    tuned = study_data.tune_report("fair_tune.tar.xz", tmp_path)
    base, arm = (tuned["results"][f"{m}@learning_rate=1e-3"] for m in ("a3c", "a3c+foresit"))
    sr, spl = (stats.paired(report.values(base, m), report.values(arm, m)) for m in ("SR", "SPL"))
    summary = " ".join((REPO / "docs" / "results.md").read_text().split())
    quote = f"a3c+foresit - a3c {study_data.interval(sr)} SR and {study_data.interval(spl)} SPL"
    assert quote in summary, quote
