"""A PureJaxRL-shaped PPO loop (the structure of purejaxrl/ppo.py: feed-forward flax MLP
actor-critic, ``lax.scan`` over ``jax.vmap(env.step)``, GAE, update epochs over shuffled
minibatches, all inside one jit) runs on GridNav-v0 as gymnax-ecosystem code gets it, with
no adapter of its own, through three wrapper stacks:

- ``envs``: ``envs.wrappers.LogWrapper`` over ``envs.make_gymnax(step_api="done")``;
- ``purejaxrl``: PureJaxRL's own ``LogWrapper(FlattenObservationWrapper(env))``
  (tests/purejaxrl_wrappers.py, verbatim; five-value step) over the same;
- ``gymnax``: ``gymnax.make("GridNav-v0", step_api="terminated_truncated")`` (the
  registry) under gymnax's own ``gymnax.wrappers.purerl``
  ``LogWrapper(FlattenObservationWrapper(env))`` (gymnax 1.x: six-value step,
  ``info["final_observation"]``).

The last two need gymnax (the ``gymnax`` extra, which CI installs) and are skipped with a
reason without it.  The episode statistics each stack logs are checked against the
rewards and GridNav's own ``info``.  A few updates only: this checks the plumbing, not
learning.  The loop is `benchmarks.reference_ppo.make_train` (the docs' PPO reference row),
here with its learning rate held fixed; the categorical distribution is written by hand
(no distrax)."""

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from benchmarks import reference_ppo
from benchmarks.reference_ppo import make_train
from envs import gymnax_compat
from envs.catalog import BATHROOM
from envs.metrics import spl as spl_term
from envs.wrappers import LogWrapper

# ppo.py's hyperparameters (`reference_ppo.CONFIG`) at a few small updates, the rate held fixed
CONFIG = dict(reference_ppo.CONFIG, NUM_ENVS=8, NUM_STEPS=32, NUM_UPDATES=4, UPDATE_EPOCHS=2, ANNEAL_LR=False)


GYMNAX = gymnax_compat.installed_gymnax_version()
ROOMS = ("bathroom",)


def envs_stack():
    env, params = envs.make_gymnax(room_types=ROOMS, step_api="done")
    return LogWrapper(env), params


def purejaxrl_stack():
    from purejaxrl_wrappers import FlattenObservationWrapper as PFlatten
    from purejaxrl_wrappers import LogWrapper as PLog

    env, params = envs.make_gymnax(room_types=ROOMS, step_api="done")
    return PLog(PFlatten(env)), params


def gymnax_stack():
    import gymnax
    from gymnax.wrappers.purerl import FlattenObservationWrapper as GFlatten
    from gymnax.wrappers.purerl import LogWrapper as GLog

    assert envs.register_gymnax()
    # gymnax 1.x's own wrappers unpack six values: its convention, one step_api away (the
    # default is five whatever is installed)
    env, params = gymnax.make("GridNav-v0", room_types=ROOMS, step_api="terminated_truncated")
    return GLog(GFlatten(env)), params


needs_gymnax = pytest.mark.skipif(GYMNAX is None, reason="gymnax is not installed (pip install -e '.[gymnax]')")
needs_gymnax_1 = pytest.mark.skipif(GYMNAX is None or GYMNAX < (1,), reason="needs gymnax >= 1.0 (its registry)")
STACKS = [
    pytest.param(envs_stack, id="envs"),
    pytest.param(purejaxrl_stack, id="purejaxrl", marks=needs_gymnax),
    pytest.param(gymnax_stack, id="gymnax", marks=needs_gymnax_1),
]


@pytest.fixture(scope="module", params=STACKS)
def ppo_run(request):
    env, env_params = request.param()
    out = jax.jit(make_train(CONFIG, env, env_params))(jax.random.key(42))
    return request.param.__name__.removesuffix("_stack"), env, env_params, jax.block_until_ready(out)


@pytest.mark.slow
def test_ppo_loop_shapes_and_finiteness(ppo_run):
    stack, env, env_params, out = ppo_run
    base = envs.GridNav()
    n = 3 * base.view_width * (base.num_semantic + 1) + 300
    assert env.observation_space(env_params).shape == (n,) and env.action_space(env_params).n == 6
    u, t, b = CONFIG["NUM_UPDATES"], CONFIG["NUM_STEPS"], CONFIG["NUM_ENVS"]
    train_state, _, last_obs, _ = out["runner_state"]
    chex.assert_shape(last_obs, (b, n))
    assert last_obs.dtype == jnp.float32
    chex.assert_shape(out["loss_info"][0], (u, CONFIG["UPDATE_EPOCHS"], CONFIG["NUM_MINIBATCHES"]))
    chex.assert_tree_all_finite((train_state.params, out["loss_info"], last_obs))
    changed = jax.tree.map(lambda a, b: bool((a != b).any()), train_state.params, out["init_params"])
    assert all(jax.tree.leaves(changed)), "every parameter should have been updated"
    metrics = out["metrics"]
    # gymnax 1.x's FlattenObservationWrapper reads final_observation at every step; the
    # five-value stacks do not ask for it, and it is not there.
    assert ("final_observation" in metrics) == (stack == "gymnax")
    keys = [
        "returned_episode",
        "returned_episode_returns",
        "returned_episode_lengths",
        "success",
        "optimal_length",
        "room_type",
        "episode_length",
        "terminated",
        "truncated",
    ]
    keys += {
        "envs": ["timestep", "returned_episode_success", "returned_episode_spl"],
        "purejaxrl": ["timestep"],
        "gymnax": ["returned_episode_valid"],
    }[stack]
    for key in keys:
        chex.assert_shape(metrics[key], (u, t, b))
    chex.assert_tree_all_finite(metrics)


@pytest.mark.slow
def test_ppo_loop_returns_the_log_wrapper_episode_statistics(ppo_run):
    stack, _, _, out = ppo_run
    m = jax.tree.map(np.asarray, out["metrics"])
    ended = m["returned_episode"].astype(bool)
    np.testing.assert_array_equal(ended, m["terminated"] | m["truncated"])
    # Training limit 30 and 4 x 32 steps per lane: every lane finishes several episodes.
    assert (ended.sum((0, 1)) >= 4).all()
    ret, length = m["returned_episode_returns"][ended], m["returned_episode_lengths"][ended]
    success = m["success"][ended]
    assert ((1 <= length) & (length <= 30)).all()
    np.testing.assert_array_equal(length, m["episode_length"][ended])
    expected = np.where(success, 5.0 - 0.01 * (length - 1), -0.01 * length).astype(np.float32)
    np.testing.assert_allclose(ret, expected, rtol=1e-5, atol=1e-5)
    assert (m["room_type"] == BATHROOM).all()
    if "timestep" in m:  # PureJaxRL counts steps since reset, this one included, across episodes
        steps = 1 + np.arange(CONFIG["NUM_UPDATES"] * CONFIG["NUM_STEPS"]).reshape(m["timestep"].shape[:2])
        np.testing.assert_array_equal(m["timestep"], np.broadcast_to(steps[..., None], m["timestep"].shape))
    if stack == "envs":
        spl = m["returned_episode_spl"][ended]
        np.testing.assert_array_equal(m["returned_episode_success"][ended], success)
        np.testing.assert_allclose(spl, spl_term(success, length, m["optimal_length"][ended]), rtol=1e-6)
        assert ((0 <= spl) & (spl <= 1)).all() and (spl[~success] == 0).all()
