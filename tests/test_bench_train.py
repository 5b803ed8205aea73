"""experiments.bench_train: the FLOP-counting path and the other helpers that do not time
anything (no timed tests: timings belong to the benchmark itself)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import train_helpers as H
from experiments import bench_train as B
from foresit_jax.agent import replay_chunk_rows


class FakeStage:
    def __init__(self, analysis):
        self.analysis = analysis

    def cost_analysis(self):
        return self.analysis


def test_xla_flops_reads_a_dict_or_a_list_of_dicts():
    assert B.xla_flops(FakeStage({"flops": 3.0, "bytes accessed": 9.0})) == 3.0
    assert B.xla_flops(FakeStage([{"flops": 3.0}, {"flops": 4.0}])) == 7.0
    assert B.xla_flops(FakeStage({})) == 0.0


def test_xla_counts_a_loop_body_once_and_the_check_sees_it():
    rolled, unrolled = B.scan_trip_count_check()
    assert unrolled == pytest.approx(10 * rolled)


def test_counting_control_flow_unrolls_scans_skips_loops_and_takes_false_branches():
    x, w = jnp.ones((4, 8)), jnp.ones((8, 8))

    def scanned(x, w):
        return jax.lax.scan(lambda c, _: (c @ w, None), x, None, length=5)[0]

    def looped(x, w):
        return jax.lax.fori_loop(0, 3, lambda i, c: c @ w, x)

    def branched(x, w):
        return jax.lax.cond(jnp.sum(x) > 0, lambda: x @ w @ w, lambda: x)

    step = B.count_flops(lambda x, w: x @ w, x, w)
    assert B.count_flops(scanned, x, w) == pytest.approx(step, abs=8)  # rolled: the body once (and a loop counter)
    originals = (jax.lax.scan, jax.lax.cond, jax.lax.while_loop, jax.lax.fori_loop)
    with B.counting_control_flow():
        assert B.count_flops(lambda x, w: scanned(x, w), x, w) == pytest.approx(5 * step, abs=8)
        assert B.count_flops(lambda x, w: looped(x, w), x, w) == 0
        assert B.count_flops(lambda x, w: branched(x, w), x, w) == 0
    assert (jax.lax.scan, jax.lax.cond, jax.lax.while_loop, jax.lax.fori_loop) == originals
    with pytest.raises(RuntimeError), B.counting_control_flow():
        raise RuntimeError
    assert (jax.lax.scan, jax.lax.cond, jax.lax.while_loop, jax.lax.fori_loop) == originals


def fake_metrics(valid_steps, trained=0):
    n = len(valid_steps)
    return {
        "losses/total_loss": np.zeros(n),
        "losses/num_valid_steps": np.asarray(valid_steps, np.float32),
        "imagination/num_trained_lanes": np.full(n, trained),
    }


@pytest.mark.parametrize("gradient", ["replay", "through_rollout"])
def test_update_flops_adds_what_ran(gradient):
    config = H.tiny_config("a3c+foresit", num_lanes=20)  # 600 steps: 4 replay chunks of 150
    env, env_params = H.bathroom_env()
    trainer = B.Trainer(config, env, env_params, gradient=gradient)
    state = H.jitted_init(config)(jax.random.PRNGKey(0))
    size = config.num_steps * config.num_lanes
    total, parts = B.update_flops(trainer, state, fake_metrics([size // 10, size // 10]))
    assert set(parts) == {"straight", "imagination", "fw_item_step"} | ({"replay_chunk"} if gradient == "replay" else set())
    assert all(value > 0 for value in parts.values())
    # Two updates, one imagination each, nothing trained, at most one replay chunk each.
    assert total == pytest.approx(2 * (parts["straight"] + parts["imagination"]))
    trained, _ = B.update_flops(trainer, state, fake_metrics([size // 10, size // 10], trained=1))
    steps = config.imagination_epochs * config.buffer_size
    assert trained - total == pytest.approx(2 * steps * parts["fw_item_step"])
    if gradient == "replay":
        rows = replay_chunk_rows(config.num_steps, config.num_lanes)
        assert -(-size // rows) == 4
        full, _ = B.update_flops(trainer, state, fake_metrics([size, size]))
        assert full - total == pytest.approx(2 * (-(-size // rows) - 1) * parts["replay_chunk"])


def test_never_done_turns_off_done_only():
    config = H.tiny_config("a3c")
    trainer = H.trainer(config)
    state = H.jitted_init(config)(jax.random.PRNGKey(0))
    forced = B.never_done(trainer, state)
    bias = forced.params["params"]["policy"]["actor"]["bias"]
    assert float(bias[-1]) == -1e9
    np.testing.assert_array_equal(bias[:-1], state.params["params"]["policy"]["actor"]["bias"][:-1])
    changed = [
        jax.tree_util.keystr(path)
        for (path, a), b in zip(jax.tree_util.tree_leaves_with_path(state.params), jax.tree.leaves(forced.params))
        if not np.array_equal(a, b)
    ]
    assert changed == ["['params']['policy']['actor']['bias']"]
