"""experiments.paper: the report at the tiny preset (every section, table, figure and claim
line, a kill and --resume on the way), the claims' verdicts on hand-made results, SR/SPL
by L^g against a brute-force count, the trajectory replay against stepping the env, and
one-line errors."""

import json
import math

import jax
import numpy as np
import pytest

import envs
from envs.metrics import LENGTH_BUCKETS, bucket_label, by_length
from experiments import paper
from experiments.running import numerics, paper_figures
from experiments.reporting import paper_tables
from cli_helpers import cli_error

# The tiny report trains two methods (compile time dominates): the other rows read "not run".
RUN = ("a3c", "a3c+foresit")
EXCLUDE = tuple(m for m in paper_tables.SETUP_OF if m not in RUN)
SECTIONS = (
    "## Platforms",
    "## Table 1",
    "### savn setup",
    "### org setup",
    "## Table 2",
    "## Table 3",
    "## Model selection",
    "## SR and SPL by optimal path length",
    "## The paper's claims",
    "## ORG's rows with sampled actions",
    "## Imagination probes",
    "## The C-VAE comparison",
    "## Figure 4",
    "## Figure 3",
    "## Learning curves",
)


# Cheap in-process CLI calls for every test of this module (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("cheap_experiments")


@pytest.mark.slow
def test_tiny_report_has_every_table_figure_and_claim_after_a_kill_resume_and_reuse(tmp_path, capsys):
    # a3c alone first, killed and resumed; then the report run trains a3c+foresit and
    # copies a3c from the first run (--reuse), as MAML rows run elsewhere would be combined.
    part, out = tmp_path / "a3c_only", tmp_path / "paper"
    extra = [
        "--cvae-windows",
        "20",
        "--cvae-epochs",
        "2",
        "--trajectory-candidates",
        "8",
        "--probe-episodes-per-room",
        "2",
        "--no-progress",
    ]
    only_a3c = ["--exclude", *EXCLUDE, "a3c+foresit"]
    argv = ["--preset", "tiny", "--seeds", "2", *extra]
    assert paper.cli([*argv, "--out", str(part), *only_a3c, "--stop-after-chunks", "1"]) is None  # killed in a3c
    assert not (part / "report.md").exists()
    # Not continued under another selection protocol than the one it was validated under.
    progress_file = part / "savn" / "methods" / "a3c" / "progress.json"
    progress = progress_file.read_text()
    progress_file.write_text(json.dumps({**json.loads(progress), "selection_protocol": 1}))
    assert "validated under selection protocol 1" in cli_error(paper.cli, ["--resume", "--out", part], capsys)
    progress_file.write_text(progress)
    paper.cli(["--resume", "--out", str(part), "--no-progress"])
    assert "a3c+foresit" in (part / "report.md").read_text().split("Not run:")[1].splitlines()[0]
    reused = (part / "savn" / "methods" / "a3c" / "results.json").read_text()
    capsys.readouterr()
    # a3c+foresit as an arm (--arms): trained in its arm's folder, reported under its method's name.
    claims = paper.cli(
        [
            *argv,
            "--out",
            str(out),
            "--exclude",
            *EXCLUDE,
            "--reuse",
            str(part),
            "--arms",
            "a3c+foresit@learning_rate=3e-4",
        ]
    )
    assert "a3c: finished in" in capsys.readouterr().out  # copied, not trained again
    assert (out / "savn" / "methods" / "a3c+foresit@learning_rate=3e-4" / "results.json").is_file()
    assert json.loads((out / "probe.json").read_text()).keys() == {"a3c+foresit"}
    assert (out / "savn" / "methods" / "a3c" / "results.json").read_text() == reused
    per_seed = json.loads((out / "savn" / "results_per_seed.json").read_text())
    assert per_seed["a3c"] == json.loads(reused)["results"]
    assert (part / "savn" / "methods" / "a3c" / "results.json").read_text() == reused  # the source untouched
    report = (out / "report.md").read_text()
    assert "(`--arms`; the rows keep the method's name): a3c+foresit at learning_rate=3e-4." in report
    for section in SECTIONS:
        assert section in report, section
    assert "Every method was trained on cpu (" in report  # a3c copied from a run on this machine
    # tiny compiles with most XLA optimisations off (`--fast-compile`), says so, and leaves the process as it was
    assert "most XLA optimisations off." in report.split("Every method was trained on cpu (")[1].splitlines()[0]
    assert not numerics.fast_compile_on()
    assert (out / "table3.csv").read_text() == ""  # none of Table 3's methods ran
    for name in (
        "table1.csv",
        "table2.csv",
        "by_length.csv",
        "claims.csv",
        "cvae_comparison.json",
        "probe.json",
        "fig4_tsne.png",
        "fig3_a3c_vs_a3c_foresit.png",
        "by_length_a3c_vs_a3c_foresit.png",
        "savn/learning_curves.png",
    ):
        assert (out / name).stat().st_size > 0, name
    assert not (out / "org").exists()  # every org method excluded: no sweep
    # One line per claim; those with a method left out read "not run".
    assert len(claims) == len(paper_tables.claims({})) == 18
    verdicts = {c: v.split(":")[0] for c, v in claims.items()}
    assert set(verdicts.values()) <= {"holds", "does not hold", "cannot tell at this budget", paper_tables.NOT_RUN}
    assert verdicts["Table 1: a3c+foresit has a higher SR than a3c"] != paper_tables.NOT_RUN
    assert verdicts["Table 3: a3c+org+foresit has a higher SR than a3c+org+att"] == paper_tables.NOT_RUN
    for claim in claims:
        assert claim in report
    for method in ("a3c+maml", "a3c+org+rnd"):
        assert any(method in line and paper_tables.NOT_RUN in line for line in report.splitlines()), method
    # Strict JSON (an empty L^g bucket is null, never NaN) with SR/SPL by L^g per seed.
    text = (out / "savn" / "results_per_seed.json").read_text()
    assert "NaN" not in text
    per_seed = json.loads(text)
    assert [r["seed"] for r in per_seed["a3c"]] == [0, 1]
    assert set(per_seed["a3c"][0]["selected"]["by_length"]) == {bucket_label(b) for b in LENGTH_BUCKETS}


def result(sr: float, sr5: float) -> dict:
    buckets = {bucket_label(b): {"SR": sr, "SPL": sr / 2, "episodes": 4} for b in LENGTH_BUCKETS}
    test = {"overall": {"SR": sr, "SPL": sr / 2, "SR>=5": sr5, "SPL>=5": sr5 / 2}, "by_length": buckets}
    return {"selected": test, "last": {**test, "overall": {**test["overall"], "SR": sr - 1.0}}}


def test_fast_compile_is_on_for_tiny_alone_unless_asked():
    assert paper.fast_compile(paper.Args(preset="tiny")) and not paper.fast_compile(paper.Args(preset="quick"))
    assert not paper.fast_compile(paper.Args(preset="tiny", fast_compile=False))
    assert paper.fast_compile(paper.Args(preset="quick", fast_compile=True))


def test_sampled_section_pairs_greedy_with_sampled_and_each_method_with_the_base():
    """The ORG rows' sampled table on hand-made numbers: sampled - greedy per method and
    each method against the base with sampled actions, as mean paired differences."""
    greedy = {"a3c+org": (60.0, 70.0, 65.0), "a3c+org+critic": (50.0, 52.0, 57.0)}
    sampled = {"a3c+org": (64.0, 73.0, 70.0), "a3c+org+critic": (62.0, 66.0, 70.0)}
    results = {
        m: [{"seed": s, "selected": {"overall": {"SR": v, "SPL": v / 2}}} for s, v in enumerate(vs)]
        for m, vs in greedy.items()
    }
    runs_ = {
        m: [{"seed": s, "overall": {"SR": v, "SPL": v / 2}} for s, v in enumerate(vs)] for m, vs in sampled.items()
    }
    md, rows = paper_tables.sampled_markdown(results, runs_)
    by = {(r["method"], r["metric"]): r for r in rows}
    assert by[("a3c+org", "SR")]["sampled - greedy"] == pytest.approx(4.0)  # (4 + 3 + 5) / 3
    assert by[("a3c+org+critic", "SR")]["sampled - greedy"] == pytest.approx(13.0)  # (12 + 14 + 13) / 3
    assert by[("a3c+org+critic", "SPL")]["greedy mean"] == pytest.approx(26.5)
    critic_line = next(line for line in md.splitlines()[-2:] if line.startswith("| a3c+org+critic"))
    assert "-3.0 [" in critic_line  # (-2 - 7 + 0) / 3 against a3c+org, sampled
    assert "+13.0 [" in md and "+4.0 [" in md


def test_claims_hold_fail_or_cannot_tell_by_the_paired_interval():
    base = [result(50.0 + d, 40.0 + d) for d in (0.0, 3.0, -2.0, 1.0)]
    better = [result(60.0 + d, 58.0 + 2 * d) for d in (0.5, 2.0, -1.0, 1.5)]  # ~+10 SR, ~+18 on L>=5, small spread
    worse = [result(40.0 + d, 30.0 + d) for d in (1.0, 2.0, -2.5, 1.0)]
    noisy = [result(50.0 + d, 40.0 + d) for d in (20.0, -20.0, 15.0, -10.0)]
    verdicts = {
        c: v
        for c, v, _ in paper_tables.claims(
            {"a3c": base, "a3c+foresit": better, "a3c+org": base, "a3c+org+foresit": worse, "a3c+org+att": noisy}
        )
    }
    assert verdicts["Table 1: a3c+foresit has a higher SR than a3c"] == "holds"
    assert verdicts["Table 1: a3c+foresit has a higher SPL than a3c"] == "holds"
    assert verdicts["a3c+foresit's SR gain over a3c is larger on L^g>=5 than overall"] == "holds"
    assert verdicts["Table 1: a3c+org+foresit has a higher SR than a3c+org"] == "does not hold"
    assert verdicts["Table 3: a3c+org+foresit has a higher SR than a3c+org+att"] == "cannot tell at this budget"
    assert verdicts["Table 1: a3c+maml has a higher SR than a3c"] == paper_tables.NOT_RUN
    # selected - last is +1 SR in every run: no spread, so no interval
    assert verdicts["Protocol: the model selected on validation has a higher test SR than the last one"] == (
        "cannot tell at this budget"
    )
    numbers = {c: n for c, _, n in paper_tables.claims({"a3c": base, "a3c+foresit": better})}
    diff = np.mean([b["selected"]["overall"]["SR"] - a["selected"]["overall"]["SR"] for a, b in zip(base, better)])
    assert numbers["Table 1: a3c+foresit has a higher SR than a3c"].startswith(f"SR difference {diff:+.1f} [")


def test_by_length_against_a_brute_force_count():
    rng = np.random.default_rng(0)
    optimal = rng.integers(1, 30, size=300)
    success = rng.random(300) < 0.4
    spl = np.where(success, rng.random(300), 0.0)
    got = by_length(success, spl, optimal)
    for (first, last), label in zip(LENGTH_BUCKETS, got):
        last = 10**9 if last is None else last
        idx = [i for i in range(300) if first <= optimal[i] <= last]
        assert got[label]["episodes"] == len(idx)
        assert got[label]["SR"] == pytest.approx(100 * sum(success[i] for i in idx) / len(idx))
        assert got[label]["SPL"] == pytest.approx(100 * sum(spl[i] for i in idx) / len(idx))
    assert sum(b["episodes"] for b in got.values()) == 300  # the buckets cover every length once
    empty = by_length([True], [1.0], [3])
    assert empty["3-4"]["SR"] == 100.0 and math.isnan(empty["15+"]["SR"]) and empty["15+"]["episodes"] == 0


def test_trajectory_replay_follows_the_environment_step_by_step():
    env, params = envs.make("GridNav-v0", setup="savn", split="test", room_types=("bathroom",), training=False)
    key = jax.random.PRNGKey(4)
    actions = jax.numpy.array([0, 0, 0, 2, 2] * 6)  # MoveAhead and turns, no Done: the episode runs on
    got = np.asarray(paper_figures.replay_positions(env, params, key, actions))
    _, state = env.reset(key, params)
    want = [np.asarray(state.agent_pos)]
    for a in np.asarray(actions):
        _, state, *_ = env.step(key, state, int(a), params)
        want.append(np.asarray(state.agent_pos))
    np.testing.assert_array_equal(got, np.stack(want))
    assert len({tuple(p) for p in want}) > 1  # the agent moved


def test_reuse_lends_each_setup_its_own_sweeps(tmp_path):
    """--reuse takes paper runs (one sweep per setup inside) and sweep folders (one setup
    each): each setup's sweep is lent the folders of that setup only."""

    def folder(path, setup=None):
        path.mkdir(parents=True)
        (path / "sweep.json").write_text(json.dumps({"setup": setup}))
        return path

    run = tmp_path / "run"
    folder(run / "savn", "savn")  # a paper run with its savn sweep only
    (run / "paper.json").write_text("{}")
    org, savn = folder(tmp_path / "org_sweep", "org"), folder(tmp_path / "savn_sweep", "savn")
    args = paper.Args(reuse=(run, org, savn))
    assert paper.reuse_sweeps(args, "savn") == (run / "savn", savn)
    assert paper.reuse_sweeps(args, "org") == (org,)
    assert paper.sweep_args(args, "org", ("a3c+org",)).reuse == (org,)


def test_arms_name_the_folders_and_the_rows_keep_the_method(tmp_path):
    args = paper.Args(arms=("a3c+foresit@learning_rate=3e-4",), out=tmp_path)
    assert paper.arm_of(args, "a3c+foresit") == "a3c+foresit@learning_rate=3e-4"
    assert paper.arm_of(args, "a3c") == "a3c"
    assert paper.sweep_args(args, "savn", ("a3c", "a3c+foresit")).methods == ("a3c", "a3c+foresit@learning_rate=3e-4")
    run = paper.paper_run(args)
    assert run.by_method({"a3c": 1, "a3c+foresit@learning_rate=3e-4": 2}) == {"a3c": 1, "a3c+foresit": 2}
    assert run.folder("a3c+foresit") == tmp_path / "savn" / "methods" / "a3c+foresit@learning_rate=3e-4"


def test_paper_rejects_bad_input_in_one_line(tmp_path, capsys):
    base = ["--preset", "tiny", "--out", tmp_path / "p"]
    assert "each arm's method must be a method of the paper's tables" in cli_error(
        paper.cli, [*base, "--arms", "a3c+critic+foresit@learning_rate=1e-3"], capsys
    )
    assert "each arm's method must be" in cli_error(
        paper.cli, [*base, "--exclude", "a3c+maml", "--arms", "a3c+maml@learning_rate=1e-3"], capsys
    )
    assert "at most one arm" in cli_error(
        paper.cli, [*base, "--arms", "a3c@learning_rate=1e-3", "a3c@learning_rate=3e-4"], capsys
    )
    assert "is not a Config field" in cli_error(paper.cli, [*base, "--arms", "a3c@no_such=1"], capsys)
    assert "not a method of the paper's tables" in cli_error(paper.cli, [*base, "--exclude", "bogus"], capsys)
    assert "leaves no method" in cli_error(paper.cli, [*base, "--exclude", *paper_tables.SETUP_OF], capsys)
    assert "--seeds must be >= 1" in cli_error(paper.cli, [*base, "--seeds", "0"], capsys)
    assert "--tsne-points must be >= 1" in cli_error(paper.cli, [*base, "--tsne-points", "0"], capsys)
    # --reuse: a folder that is neither a paper run nor a sweep, the run itself, a run of another protocol.
    assert "neither a paper run" in cli_error(paper.cli, [*base, "--reuse", tmp_path], capsys)
    other = tmp_path / "other"
    (other / "savn").mkdir(parents=True)
    (other / "paper.json").write_text("{}")
    (other / "savn" / "sweep.json").write_text(json.dumps({"setup": "savn", "preset": "quick", "seeds": 3, "seed": 0}))
    line = cli_error(paper.cli, [*base, "--seeds", "2", "--reuse", other], capsys)
    assert "another protocol" in line and "--preset quick there, tiny here" in line
    # A sweep folder is checked as its setup's source, the same way.
    sweep_folder = tmp_path / "sweep"
    sweep_folder.mkdir()
    (sweep_folder / "sweep.json").write_text(json.dumps({"setup": "org", "preset": "tiny", "num_updates": 7}))
    line = cli_error(paper.cli, [*base, "--reuse", sweep_folder], capsys)
    assert f"--reuse {sweep_folder}: run with another protocol (--num-updates 7 there, None here)" in line
    assert not (tmp_path / "p").exists()
    (tmp_path / "p").mkdir()
    (tmp_path / "p" / "paper.json").write_text("{}")
    assert "the run being written" in cli_error(paper.cli, [*base, "--overwrite", "--reuse", tmp_path / "p"], capsys)
