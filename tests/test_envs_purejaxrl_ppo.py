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
learning.  The categorical distribution is written by hand (no distrax)."""

from typing import NamedTuple

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
from flax.linen.initializers import constant, orthogonal
from flax.training.train_state import TrainState

import envs
from envs import gymnax_compat
from envs.catalog import BATHROOM
from envs.metrics import spl as spl_term
from envs.wrappers import LogWrapper

CONFIG = {
    "LR": 2.5e-4,
    "NUM_ENVS": 8,
    "NUM_STEPS": 32,
    "NUM_UPDATES": 4,
    "UPDATE_EPOCHS": 2,
    "NUM_MINIBATCHES": 4,
    "GAMMA": 0.99,
    "GAE_LAMBDA": 0.95,
    "CLIP_EPS": 0.2,
    "ENT_COEF": 0.01,
    "VF_COEF": 0.5,
    "MAX_GRAD_NORM": 0.5,
}


class ActorCritic(nn.Module):
    action_dim: int

    @nn.compact
    def __call__(self, x):
        a = nn.tanh(nn.Dense(64, kernel_init=orthogonal(np.sqrt(2)), bias_init=constant(0.0))(x))
        a = nn.tanh(nn.Dense(64, kernel_init=orthogonal(np.sqrt(2)), bias_init=constant(0.0))(a))
        logits = nn.Dense(self.action_dim, kernel_init=orthogonal(0.01), bias_init=constant(0.0))(a)
        c = nn.tanh(nn.Dense(64, kernel_init=orthogonal(np.sqrt(2)), bias_init=constant(0.0))(x))
        c = nn.tanh(nn.Dense(64, kernel_init=orthogonal(np.sqrt(2)), bias_init=constant(0.0))(c))
        value = nn.Dense(1, kernel_init=orthogonal(1.0), bias_init=constant(0.0))(c)
        return logits, jnp.squeeze(value, axis=-1)


def log_prob(logits, action):
    return jnp.take_along_axis(jax.nn.log_softmax(logits), action[..., None], -1)[..., 0]


def entropy(logits):
    logp = jax.nn.log_softmax(logits)
    return -(jnp.exp(logp) * logp).sum(-1)


class Transition(NamedTuple):
    done: jnp.ndarray
    action: jnp.ndarray
    value: jnp.ndarray
    reward: jnp.ndarray
    log_prob: jnp.ndarray
    obs: jnp.ndarray
    info: dict


def make_train(config, env, env_params):
    minibatch_size = config["NUM_ENVS"] * config["NUM_STEPS"] // config["NUM_MINIBATCHES"]

    def train(rng):
        network = ActorCritic(env.action_space(env_params).n)
        rng, _rng = jax.random.split(rng)
        init_x = jnp.zeros(env.observation_space(env_params).shape)
        network_params = network.init(_rng, init_x)
        tx = optax.chain(optax.clip_by_global_norm(config["MAX_GRAD_NORM"]), optax.adam(config["LR"], eps=1e-5))
        train_state = TrainState.create(apply_fn=network.apply, params=network_params, tx=tx)
        rng, _rng = jax.random.split(rng)
        reset_rng = jax.random.split(_rng, config["NUM_ENVS"])
        obsv, env_state = jax.vmap(env.reset, in_axes=(0, None))(reset_rng, env_params)

        def _update_step(runner_state, unused):
            def _env_step(runner_state, unused):
                train_state, env_state, last_obs, rng = runner_state
                rng, _rng = jax.random.split(rng)
                logits, value = network.apply(train_state.params, last_obs)
                action = jax.random.categorical(_rng, logits)
                logp = log_prob(logits, action)
                rng, _rng = jax.random.split(rng)
                rng_step = jax.random.split(_rng, config["NUM_ENVS"])
                # PureJaxRL unpacks five values; gymnax 1.x's wrappers give six (terminated, truncated).
                obsv, env_state, reward, *flags, info = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
                    rng_step, env_state, action, env_params
                )
                done = flags[0] | flags[1] if len(flags) == 2 else flags[0]
                transition = Transition(done, action, value, reward, logp, last_obs, info)
                return (train_state, env_state, obsv, rng), transition

            runner_state, traj_batch = jax.lax.scan(_env_step, runner_state, None, config["NUM_STEPS"])
            train_state, env_state, last_obs, rng = runner_state
            _, last_val = network.apply(train_state.params, last_obs)

            def _get_advantages(gae_and_next_value, transition):
                gae, next_value = gae_and_next_value
                done, value, reward = transition.done, transition.value, transition.reward
                delta = reward + config["GAMMA"] * next_value * (1 - done) - value
                gae = delta + config["GAMMA"] * config["GAE_LAMBDA"] * (1 - done) * gae
                return (gae, value), gae

            _, advantages = jax.lax.scan(
                _get_advantages, (jnp.zeros_like(last_val), last_val), traj_batch, reverse=True, unroll=16
            )
            targets = advantages + traj_batch.value

            def _update_epoch(update_state, unused):
                def _update_minbatch(train_state, batch_info):
                    traj_batch, advantages, targets = batch_info

                    def _loss_fn(params, traj_batch, gae, targets):
                        logits, value = network.apply(params, traj_batch.obs)
                        logp = log_prob(logits, traj_batch.action)
                        clip = config["CLIP_EPS"]
                        value_pred_clipped = traj_batch.value + (value - traj_batch.value).clip(-clip, clip)
                        value_loss = 0.5 * jnp.maximum(
                            jnp.square(value - targets), jnp.square(value_pred_clipped - targets)
                        ).mean()
                        ratio = jnp.exp(logp - traj_batch.log_prob)
                        gae = (gae - gae.mean()) / (gae.std() + 1e-8)
                        loss_actor = -jnp.minimum(ratio * gae, jnp.clip(ratio, 1.0 - clip, 1.0 + clip) * gae).mean()
                        ent = entropy(logits).mean()
                        total = loss_actor + config["VF_COEF"] * value_loss - config["ENT_COEF"] * ent
                        return total, (value_loss, loss_actor, ent)

                    grad_fn = jax.value_and_grad(_loss_fn, has_aux=True)
                    total_loss, grads = grad_fn(train_state.params, traj_batch, advantages, targets)
                    return train_state.apply_gradients(grads=grads), total_loss

                train_state, traj_batch, advantages, targets, rng = update_state
                rng, _rng = jax.random.split(rng)
                batch_size = minibatch_size * config["NUM_MINIBATCHES"]
                permutation = jax.random.permutation(_rng, batch_size)
                batch = (traj_batch, advantages, targets)
                batch = jax.tree.map(lambda x: x.reshape((batch_size,) + x.shape[2:]), batch)
                shuffled = jax.tree.map(lambda x: jnp.take(x, permutation, axis=0), batch)
                minibatches = jax.tree.map(
                    lambda x: jnp.reshape(x, [config["NUM_MINIBATCHES"], -1] + list(x.shape[1:])), shuffled
                )
                train_state, total_loss = jax.lax.scan(_update_minbatch, train_state, minibatches)
                return (train_state, traj_batch, advantages, targets, rng), total_loss

            update_state = (train_state, traj_batch, advantages, targets, rng)
            update_state, loss_info = jax.lax.scan(_update_epoch, update_state, None, config["UPDATE_EPOCHS"])
            train_state, rng = update_state[0], update_state[-1]
            return (train_state, env_state, last_obs, rng), (traj_batch.info, loss_info)

        rng, _rng = jax.random.split(rng)
        runner_state = (train_state, env_state, obsv, _rng)
        runner_state, (metric, loss_info) = jax.lax.scan(_update_step, runner_state, None, config["NUM_UPDATES"])
        return {"runner_state": runner_state, "metrics": metric, "loss_info": loss_info, "init_params": network_params}

    return train


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
    keys = ["returned_episode", "returned_episode_returns", "returned_episode_lengths", "success",
            "optimal_length", "room_type", "episode_length", "terminated", "truncated"]
    keys += {"envs": ["timestep", "returned_episode_success", "returned_episode_spl"],
             "purejaxrl": ["timestep"], "gymnax": ["returned_episode_valid"]}[stack]
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
