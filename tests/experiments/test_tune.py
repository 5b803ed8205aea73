"""experiments.tune: the grid's arms, the choice on validation only, the report's pairs
against a hand computation, reuse of a sweep that ran an arm under its plain name; end to
end on the tiny preset (slow)."""

import json

import numpy as np
import pytest
from scipy import stats as sp

from experiments import sweep, tune
from experiments.reporting import tuning
from experiments import errors
from experiments.running import sweeps

SEEDS = (0, 1, 2, 3)


def seed_result(seed, val_history, selected_update, test_sr, rng):
    """One seed's result as a sweep writes it (the fields tune reads)."""
    return {
        "seed": seed,
        "selected_update": selected_update,
        "validation": [{"update": u, "SR": sr} for u, sr in val_history],
        "selected": {"overall": {"SR": test_sr, "SPL": test_sr / 3, "SR>=5": test_sr / 2}},
        "training_success_rate": rng.uniform(0, 1, 40).tolist(),
    }


def per_seed(val_at_selected, test_sr, rng):
    """Seeds whose selected model (update 20) validates at `val_at_selected[i]`; the other
    validations are higher or lower, so only the selected one gives the right mean."""
    return [
        seed_result(s, [(10, v + 30.0), (20, v), (30, v - 30.0)], 20, t, rng)
        for s, v, t in zip(SEEDS, val_at_selected, test_sr)
    ]


def test_grid_points_and_arms():
    grid = tune.parse_grid(["learning_rate=3e-4,1e-3", "entropy_coef=0.01,0.02"])
    assert grid == [("learning_rate", ["3e-4", "1e-3"]), ("entropy_coef", ["0.01", "0.02"])]
    assert tune.points(grid) == [
        "learning_rate=3e-4,entropy_coef=0.01",
        "learning_rate=3e-4,entropy_coef=0.02",
        "learning_rate=1e-3,entropy_coef=0.01",
        "learning_rate=1e-3,entropy_coef=0.02",
    ]
    assert tune.arm("a3c", "learning_rate=3e-4") == "a3c@learning_rate=3e-4"
    assert tune.arm("a3c@imagination_input=mlp", "learning_rate=3e-4") == "a3c@imagination_input=mlp,learning_rate=3e-4"


@pytest.mark.parametrize(
    "spec, message",
    [
        (("learning_rate",), "write FIELD=V1,V2"),
        (("learning_rate=",), "write FIELD=V1,V2"),
        (("learning_rate=1e-3,1e-3",), "given twice"),
        (("learning_rate=1e-3", "learning_rate=3e-4"), "learning_rate is given twice"),
        ((), "at least one"),
    ],
)
def test_grid_errors_name_what_is_wrong(spec, message):
    with pytest.raises(errors.UserError, match=message):
        tune.parse_grid(spec)


def test_arms_are_checked_against_the_preset(tmp_path):
    args = tune.Args(methods=("a3c@learning_rate=1e-3",), out=tmp_path)
    with pytest.raises(errors.UserError, match="sets learning_rate, which --grid varies"):
        tune.arms(args, tune.parse_grid(["learning_rate=3e-4"]))
    with pytest.raises(ValueError, match="not a Config field"):
        tune.arms(tune.Args(methods=("a3c",), out=tmp_path), tune.parse_grid(["no_such_field=1"]))
    with pytest.raises(ValueError, match="is not a float"):
        tune.arms(tune.Args(methods=("a3c",), out=tmp_path), tune.parse_grid(["learning_rate=fast"]))
    with pytest.raises(errors.UserError, match="trains what it trains at learning_rate=1e-3"):
        tune.arms(tune.Args(methods=("a3c",), out=tmp_path), tune.parse_grid(["learning_rate=1e-3,0.001"]))
    table = tune.arms(
        tune.Args(methods=("a3c", "a3c+critic"), out=tmp_path), tune.parse_grid(["learning_rate=3e-4,1e-3"])
    )
    assert table["a3c+critic"] == {
        "learning_rate=3e-4": "a3c+critic@learning_rate=3e-4",
        "learning_rate=1e-3": "a3c+critic@learning_rate=1e-3",
    }


def test_the_value_is_chosen_on_validation_and_the_test_split_is_ignored():
    """Value A validates higher, B tests higher: A is chosen, and stays chosen whatever the
    test numbers are; the validation read is the selected update's, not the best or the last."""
    rng = np.random.default_rng(0)
    a = per_seed([50, 52, 48, 50], [40, 40, 40, 40], rng)
    b = per_seed([45, 47, 46, 44], [80, 80, 80, 80], rng)
    np.testing.assert_array_equal(tuning.selection_sr(a), [50, 52, 48, 50])
    assert tuning.choose({"lr=A": a, "lr=B": b}) == "lr=A"
    for r in b:
        r["selected"]["overall"]["SR"] = 0.0  # the test split turned around: no effect
    assert tuning.choose({"lr=A": a, "lr=B": b}) == "lr=A"
    for r in b:
        r["validation"][1]["SR"] = 60.0  # B's selected model now validates higher
    assert tuning.choose({"lr=A": a, "lr=B": b}) == "lr=B"
    tie = per_seed([50, 52, 48, 50], [0, 0, 0, 0], rng)
    assert tuning.choose({"lr=B": tie, "lr=A": a}) == "lr=B"  # a tie goes to the first in grid order


def test_a_seed_without_a_validation_at_its_selected_update_is_refused():
    rng = np.random.default_rng(0)
    bad = per_seed([50], [40], rng)
    bad[0]["selected_update"] = 25
    with pytest.raises(errors.UserError, match="selected update 25"):
        tuning.selection_sr(bad)


def test_report_pairs_each_method_at_its_own_value_and_at_each_common_value(tmp_path):
    """Best vs best pairs the chosen arms seed by seed (difference and t interval as a hand
    computation gives them); the common-value pairs use that value's arms."""
    rng = np.random.default_rng(1)
    grid = tune.parse_grid(["learning_rate=3e-4,1e-3"])
    table = {m: {p: tune.arm(m, p) for p in tune.points(grid)} for m in ("a3c", "a3c+foresit")}
    val = {
        ("a3c", "learning_rate=3e-4"): 40,
        ("a3c", "learning_rate=1e-3"): 60,
        ("a3c+foresit", "learning_rate=3e-4"): 55,
        ("a3c+foresit", "learning_rate=1e-3"): 50,
    }
    results = {}
    for (m, p), v in val.items():
        results[table[m][p]] = per_seed([v + rng.normal() for _ in SEEDS], rng.uniform(30, 80, len(SEEDS)), rng)
    args = tune.Args(methods=("a3c", "a3c+foresit"), out=tmp_path)
    md, out = tune.tune_report(args, grid, table, results)
    assert out["chosen"] == {"a3c": "learning_rate=1e-3", "a3c+foresit": "learning_rate=3e-4"}

    def sr(name):
        return [r["selected"]["overall"]["SR"] for r in results[name]]

    def hand(x, y):
        d = np.subtract(y, x)
        half = sp.t.ppf(0.975, len(d) - 1) * d.std(ddof=1) / np.sqrt(len(d))
        return d.mean(), d.mean() - half, d.mean() + half

    got = out["best_vs_best"]["a3c+foresit - a3c"]["SR"]
    want = hand(sr("a3c@learning_rate=1e-3"), sr("a3c+foresit@learning_rate=3e-4"))
    np.testing.assert_allclose([got["diff"], got["ci_low"], got["ci_high"]], want, rtol=1e-9)
    for point in tune.points(grid):
        got = out["common"][point]["a3c+foresit - a3c"]["SR"]
        np.testing.assert_allclose(got["diff"], np.mean(np.subtract(sr(f"a3c+foresit@{point}"), sr(f"a3c@{point}"))))
    assert "## Best vs best" in md and "a3c: learning_rate=1e-3, a3c+foresit: learning_rate=3e-4" in md
    assert "experiments.paper --arms a3c@learning_rate=1e-3 a3c+foresit@learning_rate=3e-4 --reuse" in md
    assert [r["chosen"] for r in out["grid"]] == [False, True, True, False]
    tuning.curves_png(tmp_path / "curves.png", table, results)
    assert (tmp_path / "curves.png").stat().st_size > 0


def test_reuse_finds_an_arm_under_its_plain_method_name(tmp_path):
    """`a3c` at quick trains the Config `a3c@learning_rate=1e-3` does (quick's own value):
    a sweep's folder of the one serves the other; another value finds nothing."""
    (tmp_path / "methods" / "a3c").mkdir(parents=True)
    (tmp_path / "methods" / "not an arm!").mkdir()
    args = sweep.Args(methods=("a3c@learning_rate=1e-3",), preset="quick")
    assert sweeps.method_folder(tmp_path, "a3c@learning_rate=1e-3", args) == tmp_path / "methods" / "a3c"
    assert sweeps.method_folder(tmp_path, "a3c", args) == tmp_path / "methods" / "a3c"
    missing = sweeps.method_folder(tmp_path, "a3c@learning_rate=3e-4", args)
    assert missing == tmp_path / "methods" / "a3c@learning_rate=3e-4" and not missing.exists()
    assert sweeps.method_folder(tmp_path, "a3c+critic@learning_rate=1e-3", args).name == "a3c+critic@learning_rate=1e-3"


@pytest.mark.slow
def test_tune_end_to_end_resumes_and_reuses_a_plain_sweep(tmp_path, capsys):
    """A tiny tune: the arm at the preset's own learning rate is copied from a sweep that ran
    it as plain `a3c` (nothing trained for it); the other arm stops after one chunk and
    --resume finishes it; the report chooses as `choose` does on the files; a finished tune
    is not replaced without --overwrite."""
    episodes = dict(val_episodes_per_room=4, test_episodes_per_room=4)
    plain = tmp_path / "plain"
    sweep.main(sweep.Args(methods=("a3c",), seeds=2, preset="tiny", out=plain, progress=False, **episodes))
    out = tmp_path / "tune"
    # tiny's own learning rate is Config's 1e-4
    args = tune.Args(
        methods=("a3c",),
        grid=("learning_rate=1e-4,1e-3",),
        seeds=2,
        preset="tiny",
        out=out,
        reuse=(plain,),
        progress=False,
        stop_after_chunks=1,
        **episodes,
    )
    assert tune.main(args) is None
    assert "a3c@learning_rate=1e-4: finished in" in capsys.readouterr().out
    done = tune.main(tune.Args(out=out, resume=True, progress=False))
    copied = json.loads((out / "sweep" / "methods" / "a3c@learning_rate=1e-4" / "results.json").read_text())
    assert copied == json.loads((plain / "methods" / "a3c" / "results.json").read_text())
    results = {
        p: json.loads((out / "sweep" / "methods" / f"a3c@{p}" / "results.json").read_text())["results"]
        for p in ("learning_rate=1e-4", "learning_rate=1e-3")
    }
    assert done["chosen"] == {"a3c": tuning.choose(results)}
    assert (out / "tune.md").is_file() and (out / "tune_curves.png").is_file()
    with pytest.raises(errors.UserError, match="already exists"):
        tune.main(tune.Args(methods=("a3c",), seeds=2, preset="tiny", out=out, progress=False))


def test_reuse_takes_a_tune_folder_by_its_sweep(tmp_path):
    """--reuse accepts a tune folder (tune.json inside) for its arms' sweep, a sweep folder as it is."""
    (tmp_path / "tune").mkdir()
    (tmp_path / "tune" / "tune.json").write_text("{}")
    args = tune.Args(out=tmp_path / "new", reuse=(tmp_path / "tune", tmp_path / "a_sweep"))
    assert tune.sweep_args(args, ("a3c",), tmp_path / "new" / "sweep").reuse == (
        tmp_path / "tune" / "sweep",
        tmp_path / "a_sweep",
    )


def test_tune_takes_the_scene_settings_of_a_family_from_the_command_line(tmp_path):
    """--priors and --perception-range (issue 79's family) reach every arm of the tune's sweep,
    from the command line as a user writes them."""
    import tyro

    args = tyro.cli(
        tune.Args,
        args=[
            "--methods",
            "a3c",
            "--grid",
            "learning_rate=3e-4,1e-3",
            "--priors",
            "True",
            "--perception-range",
            "4",
            "--preset",
            "tiny",
            "--out",
            str(tmp_path / "t"),
        ],
    )
    grid = tune.parse_grid(args.grid)
    for name in tune.arms(args, grid)["a3c"].values():
        config, _ = sweeps.method_schedule(name, tune.sweep_args(args, (name,), tmp_path))
        assert config.priors is True and config.perception_range == 4.0
    plain = tune.Args(methods=("a3c",), preset="tiny", out=tmp_path / "u")
    config, _ = sweeps.method_schedule("a3c", tune.sweep_args(plain, ("a3c",), tmp_path))
    assert config.priors is False and config.perception_range is None
