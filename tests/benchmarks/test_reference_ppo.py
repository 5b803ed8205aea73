"""benchmarks.reference_ppo, the docs' PPO reference row: the policy it tests acts on
GridNav's own observations exactly as the network it trained on the flat gymnax
observation, and the program runs end to end at a tiny size.  (The row's figures in
docs/results.md: tests/studies/test_reference_ppo_data.py.)"""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from benchmarks import reference_ppo as R


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
