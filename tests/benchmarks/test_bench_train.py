"""benchmarks.bench_train at a tiny size: every combination is built, compiled and run,
and the table reports the useful share the run's own metrics give (no timed assertions:
timings belong to the benchmark itself)."""

import numpy as np
import pytest

import train_helpers as H
from benchmarks import bench_train as B


@pytest.mark.slow
def test_bench_train_runs_every_combination_and_counts_useful_frames(monkeypatch, capsys):
    H.patch_for_experiments(monkeypatch)
    bench = B.BenchConfig(
        methods=("a3c",),
        preset="tiny",
        lanes=(2,),
        rollouts=("packed", "episodes"),
        gradients=("replay",),
        num_steps=8,
        updates=2,
        repeats=1,
    )
    results = B.main(bench)
    out = capsys.readouterr().out
    assert [m.label for m in results] == ["a3c packed replay", "a3c episodes replay"]
    packed, episodes = results
    assert (packed.num_steps, episodes.num_steps) == (8, 30)
    assert packed.useful_frames == packed.stepped_frames == 2 * 8 * 2  # lanes never idle
    assert 0 < episodes.useful_frames < episodes.stepped_frames == 2 * 30 * 2  # padding is stepped, not useful
    assert all(np.isfinite([m.best_s, m.compile_s, m.env_s]).all() for m in results)
    assert "| a3c packed replay | 2 | 8 |" in out and "100%" in out


@pytest.mark.parametrize("variant", ["{maml_first_order: true}", "[1]", "3"])
def test_a_variant_that_is_not_a_json_object_is_refused_before_any_compile(variant):
    with pytest.raises(ValueError, match="--variants entries must be JSON objects"):
        B.main(B.BenchConfig(preset="tiny", methods=("a3c",), variants=("{}", variant)))


@pytest.mark.slow
def test_bench_grid_times_the_arms_and_the_grid_over_the_same_frames(monkeypatch, capsys):
    from benchmarks import bench_grid

    H.patch_for_experiments(monkeypatch)
    out = bench_grid.main(
        bench_grid.BenchGrid(rates=(1e-3, 3e-3), seeds=2, method="a3c", preset="tiny", updates=2, repeats=1)
    )
    printed = capsys.readouterr().out
    assert out["rates"] == pytest.approx([1e-3, 1e-3, 3e-3, 3e-3])
    assert out["useful_frames"] > 0 and out["speedup"] > 0
    assert "| arms |" in printed and "| grid |" in printed and "2 rates x 2 seeds" in printed


def test_bench_grid_refuses_an_empty_grid_before_any_compile():
    from benchmarks import bench_grid

    with pytest.raises(ValueError, match="--rates: give at least one positive"):
        bench_grid.main(bench_grid.BenchGrid(rates=(), preset="tiny"))
