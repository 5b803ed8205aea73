"""benchmarks.reference_ppo, the docs' PPO reference row: the policy it tests acts on
GridNav's own observations exactly as the network it trained on the flat gymnax
observation, and the program runs end to end at a tiny size."""

import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from benchmarks import reference_ppo as R

REPO = Path(__file__).resolve().parents[1]


def test_the_tested_policy_sees_what_the_trained_network_saw():
    env, params = envs.make_gymnax(room_types=("bathroom",), step_api="done")
    gridnav = env.gridnav
    keys = jax.random.split(jax.random.PRNGKey(3), 5)
    flat, _ = jax.vmap(env.reset, in_axes=(0, None))(keys, params)  # what make_train's network is fed
    raw, _ = jax.vmap(gridnav.reset, in_axes=(0, None))(keys, gridnav.make_params("train", room_types=("bathroom",)))
    network = R.ActorCritic(env.num_actions)
    weights = network.init(jax.random.PRNGKey(0), flat[0])
    logits, _ = network.apply(weights, flat)
    greedy, carry = R.make_policy(gridnav, greedy=True)(weights, None, raw, jnp.ones(5, bool), jax.random.PRNGKey(1))
    assert carry is None
    np.testing.assert_array_equal(greedy, jnp.argmax(logits, -1))
    # sampled: categorical on split(key, 3)[0], apart from the environment's split(key, 3)[2]
    key = jax.random.PRNGKey(7)
    sampled, _ = R.make_policy(gridnav)(weights, None, raw, jnp.ones(5, bool), key)
    np.testing.assert_array_equal(sampled, jax.random.categorical(jax.random.split(key, 3)[0], logits))


def test_quick_frames_make_whole_updates():
    assert R.num_updates(R.CONFIG) * R.CONFIG["NUM_ENVS"] * R.CONFIG["NUM_STEPS"] == R.QUICK_FRAMES == 32 * 16 * 3000


@pytest.mark.slow
def test_the_reference_row_runs_end_to_end(tmp_path, capsys):
    out = tmp_path / "ppo.json"
    args = R.Args(seeds=(0,), learning_rates=(2.5e-4,), total_timesteps=4096, out=out)
    report = R.main(args)
    saved = json.loads(out.read_text())
    assert saved["seeds"] == [0] and saved["learning_rate"] == 2.5e-4
    assert len(saved["sampled"]["test_sr"]) == 1 and 0.0 <= saved["sampled"]["test_sr"][0] <= 100.0
    assert saved["sampled"]["tests"][0]["overall"]["episodes"] == 4 * 250  # the four room types' test episodes
    assert report["sampled"]["test_sr"] == saved["sampled"]["test_sr"]
    assert "test (sampled, lr 0.00025)" in capsys.readouterr().out
    with pytest.raises(SystemExit, match="exists"):  # nothing saved is overwritten
        R.main(args)


def test_results_md_quotes_the_reference_row(tmp_path):
    """docs/results.md's PPO reference row, recomputed from its files: the learning rate the
    validation chose, the test SR and SPL over seeds 0-4, and the pair against a3c at its
    validated 1e-3 (docs/data/fair_tune.tar.xz) on the same test episodes."""
    import study_data

    from experiments.reporting import stats

    results = (REPO / "docs" / "results.md").read_text()
    gpu = json.loads((REPO / "docs" / "data" / "reference_ppo_h200.json").read_text())
    cpu = json.loads((REPO / "docs" / "data" / "reference_ppo_epyc.json").read_text())
    assert gpu["seeds"] == [0, 1, 2, 3, 4] and gpu["ppo_config"]["TOTAL_TIMESTEPS"] == R.QUICK_FRAMES
    val = {float(lr): np.mean(v["val_sr"]) for lr, v in gpu["by_lr"].items()}
    assert max(val, key=val.get) == gpu["learning_rate"] == 2e-3
    assert (
        "| validation SR (chooses) | "
        + " | ".join(f"**{v:.1f}**" if lr == 2e-3 else f"{v:.1f}" for lr, v in sorted(val.items()))
        + " |"
        in results
    )
    cpu_val = {float(lr): np.mean(v["val_sr"]) for lr, v in cpu["by_lr"].items()}
    assert max(cpu_val, key=cpu_val.get) == max((lr for lr in val if lr in cpu_val), key=val.get)  # the same choice
    for name in ("sampled", "greedy"):
        sr, spl = stats.summary(gpu[name]["test_sr"]), stats.summary(gpu[name]["test_spl"])
        assert (
            f"| PPO, 2e-3, {name} actions | {sr['mean']:.1f} ± {sr['std']:.1f} | {spl['mean']:.1f} ± {spl['std']:.1f} |"
            in results
        )
    study_data.extract("fair_tune.tar.xz", tmp_path)
    a3c = json.loads((tmp_path / "tune" / "sweep" / "results_per_seed.json").read_text())["a3c@learning_rate=1e-3"]
    assert [r["seed"] for r in a3c] == gpu["seeds"]
    sr_pair = stats.paired([r["selected"]["overall"]["SR"] for r in a3c], gpu["sampled"]["test_sr"])
    spl_a3c = [r["selected"]["overall"]["SPL"] for r in a3c]
    spl_pair = stats.paired(spl_a3c, gpu["sampled"]["test_spl"])
    assert f"sampled PPO - a3c is {study_data.interval(sr_pair)} SR" in results
    mde = stats.minimum_detectable_effect(float(np.std(np.subtract(gpu["sampled"]["test_spl"], spl_a3c), ddof=1)), 5)
    assert f"On SPL, {study_data.interval(spl_pair)}: cannot tell (MDE {mde:.1f})" in results.replace("\n", " ")
