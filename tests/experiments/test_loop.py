"""experiments.running.loop, the parts of the run loop train and sweep share (`Run.train`):
chunking and the chunk budget, the non-finite stop (naming update, seed and the last
checkpoint), divergence warnings, and where a resume continues (the newest intact checkpoint the records cover). Fake
`run` functions in numpy, and real orbax checkpoints of small trees: no training."""

import numpy as np
import pytest

from experiments.running import checkpoint, loop


def fake_run(nan_at=None, nan_params_after=None, seeds=None):
    """A `Trainer.run` stand-in: the state counts updates; the loss is the update index;
    NaN in the loss at update `nan_at` (1-based, of `seeds[0]`'s row when stacked), or in
    the parameters once the count passes `nan_params_after`."""
    calls = []

    def run(state, env_params, n):
        calls.append(n)
        start = int(np.max(state["count"]))
        loss = np.arange(start + 1, start + n + 1, dtype=np.float32)
        if nan_at is not None and start < nan_at <= start + n:
            loss[nan_at - start - 1] = np.nan
        count = state["count"] + n
        w = state["w"].copy()
        if nan_params_after is not None and start + n > nan_params_after:
            w[..., 0] = np.inf
        metrics = {
            "losses/total_loss": loss if seeds is None else np.stack([np.full(n, 1.0, np.float32), loss]),
            "losses/grad_norm": np.ones_like(loss),
            "losses/entropy": np.ones_like(loss),
        }
        return {"count": count, "w": w}, metrics

    return run, calls


class NoCheckpoints:
    def latest_step(self):
        return None


def run_loop(
    run,
    state,
    *,
    done,
    total,
    chunk_updates,
    manager=None,
    checkpoints="c",
    seeds=None,
    budget=None,
    label="",
    seen=None,
):
    """`Run.train`'s loop over a fake `run`: [(the state after each chunk, its `Chunk`)], as
    recorded (appended to `seen` as they are)."""
    seen = [] if seen is None else seen
    for n in loop.chunk_sizes(done, total, chunk_updates, budget):
        state, metrics = run(state, None, n)
        warning = loop.check(
            metrics,
            state,
            done,
            n,
            manager=manager or NoCheckpoints(),
            checkpoints=checkpoints,
            seeds=seeds,
            label=label,
        )
        done += n
        seen.append((state, loop.Chunk(metrics, done, n, warning, 0.0)))
    return seen


def test_chunks_cover_the_updates_and_the_budget_stops_between_them():
    run, calls = fake_run()
    seen = run_loop(run, {"count": np.int32(0), "w": np.ones(3, np.float32)}, done=0, total=10, chunk_updates=4)
    assert calls == [4, 4, 2] and int(seen[-1][0]["count"]) == 10
    assert [(int(s["count"]), c.done, c.n) for s, c in seen] == [(4, 4, 4), (8, 8, 4), (10, 10, 2)]
    assert list(loop.chunk_sizes(0, 10, 4)) == [4, 4, 2] and list(loop.chunk_sizes(10, 10, 4)) == []
    budget = [2]
    run, calls = fake_run()
    seen = run_loop(
        run, {"count": np.int32(3), "w": np.ones(3, np.float32)}, done=3, total=10, chunk_updates=2, budget=budget
    )
    assert (calls, seen[-1][1].done, budget) == ([2, 2], 7, [0])
    run, calls = fake_run()
    assert run_loop(run, {"count": np.int32(0), "w": np.ones(1)}, done=0, total=5, chunk_updates=5, budget=[0]) == []
    assert calls == []
    budget = [1]  # spent when the loop's body over a chunk has returned, not before
    sizes = loop.chunk_sizes(0, 10, 4, budget)
    assert next(sizes) == 4 and budget == [1]
    assert list(sizes) == [] and budget == [0]


def test_nonfinite_names_the_update_and_the_seed():
    finite = {"w": np.ones((2, 3), np.float32)}
    assert loop.nonfinite({"losses/total_loss": np.ones(4)}, {"w": np.ones(3)}, 8, 4) is None
    assert loop.nonfinite({"losses/total_loss": [1.0, 2.0, np.nan, np.inf]}, {"w": np.ones(3)}, 8, 4) == (
        "non-finite loss at update 11"
    )
    loss = np.ones((2, 4))
    loss[1, 1] = np.nan
    assert (
        loop.nonfinite({"losses/total_loss": loss}, finite, 8, 4, seeds=[5, 6])
        == "non-finite loss at update 10 of seed 6"
    )
    bad = {"w": np.ones((2, 3), np.float32)}
    bad["w"][0, 2] = np.nan
    line = loop.nonfinite({"losses/total_loss": np.ones((2, 4))}, bad, 8, 4, seeds=[5, 6])
    assert line.startswith("non-finite parameters after update 12 in seed(s) [5]"), line
    line = loop.nonfinite({"losses/total_loss": np.ones(4)}, {"w": np.array([np.inf])}, 0, 4)
    assert line.startswith("non-finite parameters after update 4 ("), line


def test_a_non_finite_chunk_stops_before_it_is_recorded(capsys):
    class Manager:
        def latest_step(self):
            return 4

    run, _ = fake_run(nan_at=6, seeds=[3, 7])
    seen = []
    with pytest.raises(SystemExit) as stop:
        run_loop(
            run,
            {"count": np.zeros(2, np.int32), "w": np.ones((2, 3), np.float32)},
            done=0,
            total=9,
            chunk_updates=4,
            manager=Manager(),
            checkpoints="runs/x/checkpoints",
            seeds=[3, 7],
            label="a3c: ",
            seen=seen,
        )
    assert stop.value.code == 1 and [c.done for _, c in seen] == [4]  # the second chunk is not recorded
    err = capsys.readouterr().err
    assert (
        "a3c: non-finite loss at update 6 of seed 7; training stopped, its last checkpoint (update 4, finite) "
        "is kept in runs/x/checkpoints"
    ) in err, err
    run, _ = fake_run(nan_params_after=0)
    with pytest.raises(SystemExit):
        run_loop(run, {"count": np.int32(0), "w": np.ones(3, np.float32)}, done=0, total=9, chunk_updates=4)
    assert "non-finite parameters after update 4" in capsys.readouterr().err


def test_divergence_short_of_nan_is_warned_and_handed_on(capsys):
    def run(state, env_params, n):
        return state, {"losses/total_loss": np.full(n, 1e9), "losses/entropy": np.ones(n)}

    seen = run_loop(run, {"w": np.ones(1, np.float32)}, done=2, total=4, chunk_updates=2)
    assert "total_loss reached 1e+09" in seen[0][1].warning
    assert "warning: updates 3-4: training may be diverging" in capsys.readouterr().err


def checkpoints(tmp_path, steps):
    manager = checkpoint.checkpoint_manager(tmp_path / "ckpt", 10)
    for step in steps:
        checkpoint.save(manager, step, {"w": np.full(3, step, np.float32)})
    manager.wait_until_finished()
    return manager


def truncate(manager, step):
    data = max(
        (
            p
            for p in checkpoint.step_dir(manager, step).rglob("*")
            if p.is_file() and p.name != checkpoint.CHECKSUM_FILE
        ),
        key=lambda p: p.stat().st_size,
    )
    data.write_bytes(data.read_bytes()[: data.stat().st_size // 2])


def test_a_resume_continues_from_the_newest_intact_checkpoint_the_records_cover(tmp_path, capsys):
    manager = checkpoints(tmp_path, [2, 4, 6])
    assert loop.resume_point(manager, tmp_path / "ckpt", recorded=4) == 4  # 6: saved, never recorded
    assert manager.all_steps() == [2, 4] and capsys.readouterr().err == ""
    truncate(manager, 4)
    assert loop.resume_point(manager, tmp_path / "ckpt", label="a3c: ") == 2
    err = capsys.readouterr().err
    assert "a3c: checkpoint" in err and "skipped" in err and "a3c: continuing from update 2" in err, err
    assert manager.all_steps() == [2]
    truncate(manager, 2)
    assert loop.resume_point(manager, tmp_path / "ckpt") == 0 and manager.all_steps() == []
    assert "no intact checkpoint in" in capsys.readouterr().err
    manager = checkpoints(tmp_path, [2])
    fresh = checkpoint.checkpoint_manager(tmp_path / "none", 10)
    assert loop.resume_point(fresh, tmp_path / "none") == 0 and capsys.readouterr().err == ""
    assert loop.resume_point(fresh, tmp_path / "none", recorded=2) == 0  # recorded, but the checkpoint is gone
    assert "no checkpoint in" in capsys.readouterr().err
    assert loop.resume_point(manager, tmp_path / "ckpt", recorded=0) == 0  # killed before the first records
    assert manager.all_steps() == [] and capsys.readouterr().err == ""
