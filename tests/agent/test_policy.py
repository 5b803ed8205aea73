"""The agent as a step-by-step policy (`foresit_jax.policy.policy`; the maml base's
`maml.policy`), any policy on the reports' episodes (`evaluate.evaluate_policy`), and a
trained policy loaded from a run folder
(`experiments.load`): each replays what the library's own rollout and evaluation play,
exactly (issue 61).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import train_helpers as H
from foresit_jax import maml, policy, rollout
from foresit_jax.evaluate import Evaluator, evaluate_policy, policy_episodes
from foresit_jax.networks import build
from foresit_jax.rollout import AgentParams, BoundEnv, episode_stats

DONE = 5  # GridNav's Done action


def _same(a, b) -> bool:
    """Equal nested results, NaN equal to NaN (a length bucket with no episode)."""
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return a == b or (isinstance(a, float) and math.isnan(a) and math.isnan(b))


def _acting(config, done_bias: float = 1.5):
    """(nets, AgentParams with noise 0.3 and a Done bias so that episodes end at many lengths)."""
    nets = build(config)
    env, env_params = H.bathroom_env()
    obs, _ = env.reset(jax.random.PRNGKey(0), env_params)
    params, w_params = nets.init(jax.random.PRNGKey(1), obs)
    params = jax.tree.map(lambda x: x, params)
    bias = params["params"]["policy"]["actor"]["bias"]
    params["params"]["policy"]["actor"]["bias"] = bias.at[DONE].set(done_bias)
    return nets, AgentParams(params, w_params, jnp.float32(0.3)), env, env_params


@pytest.mark.slow  # 14 s cold for a3c+foresit (docs/testing.md)
@pytest.mark.parametrize("method", ["a3c+foresit", "a3c+oracle", "int"])
def test_the_policy_step_by_step_plays_rollouts_episodes_exactly(method):
    config = H.tiny_config(method)
    nets, acting, env, env_params = _acting(config)
    lanes, steps, key = 12, 30, jax.random.PRNGKey(5)
    bound = rollout.acting_env(nets, BoundEnv(env, env_params))
    acting = acting._replace(noise_variance=jnp.full(lanes, acting.noise_variance))
    want = jax.jit(
        lambda a: episode_stats(rollout.rollout(nets, a, bound, key, steps)), compiler_options=H.FAST_COMPILE
    )(acting)
    act = policy.policy(nets)
    got = jax.jit(
        lambda a: policy_episodes(act, a, policy.policy_carry(nets, lanes), bound, key, steps, lanes),
        compiler_options=H.FAST_COMPILE,
    )(acting)
    for name in ("success", "length", "optimal_length", "ended", "spl", "room_type"):
        np.testing.assert_array_equal(np.asarray(getattr(got, name)), np.asarray(getattr(want, name)), err_msg=name)
    lengths = np.asarray(want.length)
    assert len(set(lengths.tolist())) >= 3, lengths  # the episodes differ: every step's keys mattered


@pytest.mark.slow
@pytest.mark.parametrize("method", ["a3c+maml", "a3c+maml+foresit"])
def test_the_maml_policy_adapts_in_its_carry_and_plays_rollouts_episodes_exactly(method):
    """The maml base step by step: each lane's theta_i in the carry, updated after steps 6,
    12, 18, 24 of its episode from the segment it replays. At a large inner rate (1e4, so
    that the updates change actions) it plays `rollout`'s episodes exactly, and those
    differ from the same episodes at SAVN's rate: the updates it replays mattered."""
    config = dataclasses.replace(H.tiny_config(method), maml_inner_lr=1e4)
    nets, acting, env, env_params = _acting(config, done_bias=-2.0)
    lanes, steps, key = 12, 30, jax.random.PRNGKey(5)
    bound = BoundEnv(env, env_params)
    obs, _ = env.reset(jax.random.PRNGKey(0), env_params)

    def played(nets):
        return jax.jit(
            lambda a: episode_stats(rollout.rollout(nets, a, bound, key, steps, act=maml.act)),
            compiler_options=H.FAST_COMPILE,
        )(acting)

    acting = acting._replace(noise_variance=jnp.full(lanes, acting.noise_variance))
    want = played(nets)
    act = maml.policy(nets)
    carry = maml.policy_carry(nets, lanes, acting, jax.eval_shape(lambda: obs))
    got = jax.jit(lambda a, c: policy_episodes(act, a, c, bound, key, steps, lanes), compiler_options=H.FAST_COMPILE)(
        acting, carry
    )
    for name in ("success", "length", "optimal_length", "ended", "spl", "room_type"):
        np.testing.assert_array_equal(np.asarray(getattr(got, name)), np.asarray(getattr(want, name)), err_msg=name)
    lengths = np.asarray(want.length)
    assert np.sum(lengths > 12) >= 3, lengths  # episodes long enough for two updates or more
    savn = played(build(H.tiny_config(method)))  # the default inner rate, 1e-4
    assert not np.array_equal(np.asarray(savn.length), lengths), lengths


def test_the_maml_keys_are_adaptive_acts():
    """`adaptive_keys` by hand: segment j's key is split(key, slots + 1)[j], split per lane,
    then per step; the environment's is split(split(step key, 3)[2], 1)[0]."""
    loop, key, lanes, steps = (
        maml.InnerLoop(segment=2, updates=2, lr=1.0, first_order=False),
        jax.random.PRNGKey(3),
        3,
        7,
    )
    policy_keys, env_keys = maml.adaptive_keys(loop, key, steps, lanes)
    assert policy_keys.shape == (steps, lanes, 2) and env_keys.shape == (steps, lanes, 2)
    segments = jax.random.split(key, 3)  # slots after steps 2 and 4, then the rest (3 steps)
    for t, (j, n, i) in enumerate([(0, 2, 0), (0, 2, 1), (1, 2, 0), (1, 2, 1), (2, 3, 0), (2, 3, 1), (2, 3, 2)]):
        for b in range(lanes):
            want = jax.random.split(jax.random.split(segments[j], lanes)[b], n)[i]
            np.testing.assert_array_equal(np.asarray(policy_keys[t, b]), np.asarray(want))
            env_want = jax.random.split(jax.random.split(want, 3)[2], 1)[0]
            np.testing.assert_array_equal(np.asarray(env_keys[t, b]), np.asarray(env_want))


def test_the_maml_carry_needs_its_parameters_and_a_missing_noise_variance_is_refused():
    maml_nets = build(H.tiny_config("a3c+maml"))
    with pytest.raises(ValueError, match="maml base"):
        maml.policy_carry(maml_nets, 2)
    for wrong in (policy.policy, policy.policy_carry):  # the a3c base's step cannot run the maml base
        with pytest.raises(ValueError, match="foresit_jax.maml"):
            wrong(maml_nets, 2)
    nets = build(H.tiny_config("a3c+foresit"))  # refused before the parameters or observations are read
    with pytest.raises(ValueError, match="noise_variance"):
        policy.policy(nets)(
            AgentParams(None, None, None), policy.policy_carry(nets, 2), None, jnp.ones(2, bool), jax.random.PRNGKey(0)
        )


@pytest.mark.slow
def test_evaluate_policy_gives_the_evaluators_numbers():
    config = H.tiny_config("a3c+foresit")
    nets, acting, _, _ = _acting(config)
    key = jax.random.PRNGKey(9)
    want = Evaluator.for_config(config).evaluate(acting, config, "test", key, 8, by_length=True)
    got = evaluate_policy(
        policy.policy(nets), acting, functools.partial(policy.policy_carry, nets), config, "test", key, 8
    )
    assert _same(got, want), (got, want)
    assert 0.0 < want["overall"]["SR"] + want["overall"]["episodes"]


def test_a_users_own_policy_runs_on_the_same_episodes():
    """Hand-checkable policies: always Done ends every episode after one action; always
    turning (action 1) never succeeds and runs to the time limit."""
    config = H.tiny_config("a3c")
    env, env_params = H.bathroom_env()
    bound, lanes, steps = BoundEnv(env, env_params), 6, 30

    def constant(action):
        return lambda params, carry, obs, first, key: (jnp.full(first.shape, action, jnp.int32), carry)

    done = policy_episodes(constant(DONE), None, (), bound, jax.random.PRNGKey(2), steps, lanes)
    np.testing.assert_array_equal(np.asarray(done.length), 1)
    assert bool(np.all(done.ended))
    turn = policy_episodes(constant(1), None, (), bound, jax.random.PRNGKey(2), steps, lanes)
    assert not np.any(turn.success) and bool(np.all(turn.ended))
    np.testing.assert_array_equal(np.asarray(turn.length), int(np.max(env_params.max_steps)))
    report = evaluate_policy(constant(DONE), None, lambda n: (), config, "test", jax.random.PRNGKey(2), 6)
    assert report["overall"]["episodes"] == 6 and 0.0 <= report["overall"]["SR"] <= 100.0


@pytest.mark.slow
@pytest.mark.parametrize("method", ["a3c+foresit", "a3c+maml"])
def test_load_reproduces_the_runs_test_results(tmp_path, method):
    """A tiny run trained by the CLI, loaded (`experiments.load`, the selected and the last
    model) and evaluated on its test episodes: the numbers its results.json reports (the
    maml base adapting step by step in its carry)."""
    import experiments
    from experiments import train as train_cli
    from experiments.errors import UserError

    out = tmp_path / "run"
    train_cli.main(train_cli.Args(method=method, preset="tiny", seed=3, out=out, progress=False))
    results = json.loads((out / "results.json").read_text())["results"][0]
    for which, reported in (("best", "selected"), ("last", "last")):
        loaded = experiments.load(out, seed=3, which=which)
        got = evaluate_policy(
            loaded.act,
            loaded.params,
            loaded.initial_carry,
            loaded.config,
            "test",
            loaded.test_key,
            loaded.test_episodes_per_room,
        )
        for metric in ("SR", "SPL"):
            assert got["overall"][metric] == pytest.approx(results[reported]["overall"][metric], abs=1e-9), which
    with pytest.raises(UserError, match="seeds"):
        experiments.load(out, seed=4)
    with pytest.raises(UserError, match="which"):
        experiments.load(out, which="first")
    with pytest.raises(UserError, match="not a run folder"):
        experiments.load(tmp_path)


@pytest.mark.slow  # trains two seeds of tiny for 2 updates, then evaluates
def test_make_act_is_the_policy_make_train_trained():
    """rejax's `make_act`, here: from the states `jax.vmap(train)(keys)` returns, seed 1's
    policy in memory plays the evaluator's own episodes of seed 1's last parameters."""
    from foresit_jax.evaluate import agent_params, make_act
    from foresit_jax.train import make_train

    config = H.tiny_config("a3c+foresit", num_updates=2)
    states, _ = jax.jit(jax.vmap(make_train(config)))(jax.random.split(jax.random.PRNGKey(0), 2))
    act = make_act(config, states, seed=1)
    one = jax.tree.map(lambda x: x[1], states)
    H.assert_trees_bitwise_equal(act.params.params, one.params)
    key = jax.random.PRNGKey(9)
    want = Evaluator.for_config(config).evaluate(
        agent_params(one, config.sigma2_max, config.evaluation_noise), config, "test", key, 8, by_length=True
    )
    got = evaluate_policy(act.act, act.params, act.initial_carry, config, "test", key, 8)
    assert _same(got, want), (got, want)
    assert make_act(config, one).params.noise_variance == act.params.noise_variance


def test_make_act_asks_for_a_seed_exactly_when_the_states_hold_several():
    from types import SimpleNamespace

    from foresit_jax.evaluate import make_act

    config = H.tiny_config("a3c+foresit")
    with pytest.raises(ValueError, match=r"give seed=i .* has shape \(3,\)"):
        make_act(config, SimpleNamespace(update=np.zeros(3)))
    with pytest.raises(ValueError, match=r"give seed=i .* has shape \(\)"):
        make_act(config, SimpleNamespace(update=np.zeros(())), seed=0)
    with pytest.raises(ValueError, match="seed 3 is not one of the 3 seeds"):
        make_act(config, SimpleNamespace(update=np.zeros(3)), seed=3)
