"""A perception range in the env (`GridNav(perception_range=R)`, issue 58's lever): object
pixels deeper than R show one more class, everything else as without it; checked against
the foresight tool's numpy emulation (`experiments.foresight.within_range`, which measured
the lever) on the same states, in both view paths, in the observation and org's
detections; the option reaching the Config, the trainer's env and the Evaluator; bad values
refused."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from envs import catalog as C
from experiments.reporting.foresight_bound import within_range
from foresit_jax import train as T
from foresit_jax.config import Config
from foresit_jax.evaluate import Evaluator


def views(env, params, states):
    return jax.tree.map(np.asarray, jax.vmap(lambda s: env.view(s, params))(states))


@pytest.mark.parametrize(
    "setup,priors,precomputed",
    [("savn", True, True), pytest.param("savn", True, False, marks=pytest.mark.slow), ("org", False, True)],
)
def test_the_view_is_the_tools_emulation_of_the_range(setup, priors, precomputed):
    # test_priors' small bank (one room type, 3 rays), so that the bank cache is shared
    kw = dict(setup=setup, priors=priors, precomputed_views=precomputed, view_width=3)
    plain, ranged = envs.GridNav(**kw), envs.GridNav(perception_range=4.0, **kw)
    params = plain.make_params("val", room_types=("bedroom",))
    keys = jax.random.split(jax.random.PRNGKey(3), 256)
    _, states = jax.vmap(lambda k: plain.reset(k, params))(keys)
    # a few steps in, so the views are not only first views
    states = jax.vmap(lambda k, s: plain.step(k, s, jnp.int32(C.ROTATE_LEFT), params)[1])(keys, states)
    sem, depth = views(plain, params, states)
    sem_r, depth_r = views(ranged, params, states)
    expected, classes = within_range(sem, depth, 4.0, plain.num_semantic, plain.num_categories, C.NUM_STRUCTURAL)
    np.testing.assert_array_equal(sem_r, expected)
    np.testing.assert_array_equal(depth_r, depth)
    assert ranged.num_semantic == classes == plain.num_semantic + 1 == ranged.unresolved_class + 1
    # not vacuous: objects are seen both near (resolved) and far (unresolved)
    is_object = (sem >= C.NUM_STRUCTURAL) & (sem < C.NUM_STRUCTURAL + plain.num_categories)
    assert (is_object & (depth > 4.0)).sum() > 20 and (is_object & (depth <= 4.0)).sum() > 20
    assert ((sem_r == ranged.unresolved_class) == (is_object & (depth > 4.0))).all()


def test_the_observation_and_detections_follow_the_ranged_view():
    plain, ranged = envs.GridNav(setup="org", view_width=3), envs.GridNav(setup="org", view_width=3, perception_range=6)
    params = plain.make_params("val", room_types=("bedroom",))
    keys = jax.random.split(jax.random.PRNGKey(5), 128)
    obs, states = jax.vmap(lambda k: ranged.reset(k, params))(keys)
    space = ranged.observation_space(params)
    assert obs["view"].shape[1:] == space["view"].shape == (3, ranged.view_width, ranged.num_semantic + 1)
    sem, depth = views(ranged, params, states)
    np.testing.assert_array_equal(np.asarray(obs["view"][..., :-1]).argmax(-1), sem)
    np.testing.assert_array_equal(np.asarray(obs["view"][..., :-1]).sum(-1), 1.0)
    detections = jax.vmap(ranged.detections)(jnp.asarray(sem), jnp.asarray(depth), states.target)
    np.testing.assert_array_equal(np.asarray(obs["detections"]), np.asarray(detections))
    # a category is detected only where some pixel of it lies within the range
    visible = np.asarray(obs["detections"][..., 0]) > 0
    cats = C.NUM_STRUCTURAL + np.arange(ranged.num_categories)
    near = (sem[:, None] == cats[None, :, None, None]).any((2, 3))
    np.testing.assert_array_equal(visible, near)
    plain_sem, _ = views(plain, params, states)
    far_only = (plain_sem[:, None] == cats[None, :, None, None]).any((2, 3)) & ~near
    assert far_only.any()  # some category the plain view detects is out of range here


@pytest.mark.parametrize("bad", [0, -1.0, float("inf"), float("nan"), True, "4"])
def test_a_bad_range_is_refused_by_the_env_and_the_config(bad):
    with pytest.raises(ValueError, match="perception_range"):
        envs.GridNav(perception_range=bad)
    with pytest.raises(ValueError, match="perception_range"):
        Config(perception_range=bad)


def test_the_config_reaches_the_trainers_env_and_the_evaluator():
    config = Config(priors=True, perception_range=4.0)
    env, _ = T.make_env(config, split="val")
    assert env.perception_range == 4.0 and env.num_semantic == C.num_semantic("savn", True) + 1
    assert T.make_env(Config(priors=True), split="val")[0].perception_range is None
    evaluator = Evaluator.for_config(config)
    assert evaluator.env.perception_range == 4.0
    with pytest.raises(ValueError, match="perception_range"):
        evaluator._check(dataclasses.replace(config, perception_range=None), "test", 1)


def test_the_range_changes_only_what_is_seen():
    """Same keys and actions with and without the range: the same states, rewards, ends and
    per-episode facts (so the layouts, starts, oracle, success and the calibration of
    test_env_calibration are the family's too); only the views' classes differ."""
    kw = dict(setup="savn", priors=True, view_width=3)
    plain, ranged = envs.GridNav(**kw), envs.GridNav(perception_range=4.0, **kw)
    params = plain.make_params("val", room_types=("bedroom",))
    keys = jax.random.split(jax.random.PRNGKey(11), 64)

    def play(env):
        obs, state = jax.vmap(lambda k: env.reset(k, params))(keys)

        def body(state, t):
            step_keys = jax.vmap(lambda k: jax.random.fold_in(k, t))(keys)
            action = jax.random.randint(jax.random.fold_in(keys[0], t), (64,), 0, C.NUM_ACTIONS)
            obs, state, reward, terminated, truncated, info = jax.vmap(lambda k, s, a: env.step(k, s, a, params))(
                step_keys, state, action
            )
            info = {k: v for k, v in info.items() if k != "final_observation"}
            return state, (state, reward, terminated, truncated, info, obs["view"].argmax(-1))

        return jax.lax.scan(body, state, jnp.arange(60))[1]

    (*same_plain, sem_plain), (*same_ranged, sem_ranged) = play(plain), play(ranged)
    jax.tree.map(lambda a, b: np.testing.assert_array_equal(np.asarray(a), np.asarray(b)), same_plain, same_ranged)
    assert np.asarray(same_plain[2] | same_plain[3]).any()  # episodes ended and auto-reset inside the 60 steps
    differ = np.asarray(sem_plain != sem_ranged)
    assert differ.any() and (np.asarray(sem_ranged)[differ] == ranged.unresolved_class).all()
