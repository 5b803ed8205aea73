"""A reference row users know: PureJaxRL's PPO on GridNav-v0, on quick's frames, tested on
the reports' own episodes.

    python -m benchmarks.reference_ppo --seeds 0 1 2 3 4 --out runs/reference_ppo.json

`make_train` is the structure of PureJaxRL's `purejaxrl/ppo.py` (Lu et al. 2022, Apache-2.0):
a feed-forward tanh MLP actor-critic (two 64-unit layers each), `lax.scan` over
`jax.vmap(env.step)`, GAE, update epochs over shuffled minibatches, all in one jit, with
its defaults (learning rate 2.5e-4 annealed linearly, 128 steps, 4 epochs of 4
minibatches, clip 0.2, entropy 0.01, gradient norm 0.5). The categorical distribution is
written by hand (no distrax). It runs on `envs.make_gymnax`'s five-value step, the
training split's scenes of the quick preset (savn setup, the four room types, training
time limits), with no adapter.

What differs from ppo.py, and why: 32 environments (quick's lanes) and `TOTAL_TIMESTEPS` = quick's frames,
32 lanes x 16 steps x 3000 updates = 1,536,000 per seed; the learning rate is chosen
from `--learning-rates` by the mean validation SR over the seeds (the project's
validation episodes of each seed, `experiments.running.selection.validation_key`), as
the project's arms are. The last model is tested (PPO keeps no checkpoints here), on
`foresit_jax.evaluate.evaluate_policy`'s test episodes of each seed
(`selection.test_key(seed)`, 250 per room type): the very episodes the a3c rows of
docs/results.md were tested on. Actions are sampled (PureJaxRL's policy is stochastic;
a feed-forward policy acting greedily repeats itself wherever two views look alike);
`--greedy` tests the argmax as well.

The policy has no memory (ppo.py's network): the row says what a standard on-policy
learner without recurrence reaches on these frames, not what PPO with an LSTM would.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path
from typing import NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import optax
import tyro
from flax.linen.initializers import constant, orthogonal
from flax.training.train_state import TrainState

import envs
from envs.wrappers import FlattenObservationWrapper
from experiments.reporting import stats
from experiments.running import selection
from experiments.running.presets import preset
from foresit_jax.evaluate import evaluate_policy

QUICK_FRAMES = 32 * 16 * 3000

CONFIG = {  # purejaxrl/ppo.py's defaults, but NUM_ENVS and TOTAL_TIMESTEPS (module docstring)
    "LR": 2.5e-4,
    "NUM_ENVS": 32,
    "NUM_STEPS": 128,
    "TOTAL_TIMESTEPS": QUICK_FRAMES,
    "UPDATE_EPOCHS": 4,
    "NUM_MINIBATCHES": 4,
    "GAMMA": 0.99,
    "GAE_LAMBDA": 0.95,
    "CLIP_EPS": 0.2,
    "ENT_COEF": 0.01,
    "VF_COEF": 0.5,
    "MAX_GRAD_NORM": 0.5,
    "ANNEAL_LR": True,
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


def num_updates(config) -> int:
    """ppo.py's `NUM_UPDATES`: TOTAL_TIMESTEPS // NUM_STEPS // NUM_ENVS (or given)."""
    return config.get("NUM_UPDATES") or config["TOTAL_TIMESTEPS"] // config["NUM_STEPS"] // config["NUM_ENVS"]


def make_train(config, env, env_params):
    """ppo.py's `make_train`: `train(rng) -> {"runner_state", "metrics", "loss_info",
    "init_params"}`, jittable and vmappable over `rng`. Steps with five values (PureJaxRL's)
    or six (gymnax 1.x's: terminated, truncated)."""
    updates = num_updates(config)
    minibatch_size = config["NUM_ENVS"] * config["NUM_STEPS"] // config["NUM_MINIBATCHES"]

    def linear_schedule(count):
        frac = 1.0 - (count // (config["NUM_MINIBATCHES"] * config["UPDATE_EPOCHS"])) / updates
        return config["LR"] * frac

    def train(rng):
        network = ActorCritic(env.action_space(env_params).n)
        rng, _rng = jax.random.split(rng)
        init_x = jnp.zeros(env.observation_space(env_params).shape)
        network_params = network.init(_rng, init_x)
        lr = linear_schedule if config.get("ANNEAL_LR", False) else config["LR"]
        tx = optax.chain(optax.clip_by_global_norm(config["MAX_GRAD_NORM"]), optax.adam(lr, eps=1e-5))
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
                        value_loss = (
                            0.5
                            * jnp.maximum(jnp.square(value - targets), jnp.square(value_pred_clipped - targets)).mean()
                        )
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
        runner_state, (metric, loss_info) = jax.lax.scan(_update_step, runner_state, None, updates)
        return {"runner_state": runner_state, "metrics": metric, "loss_info": loss_info, "init_params": network_params}

    return train


def make_policy(env, greedy: bool = False):
    """The trained network as `evaluate_policy`'s policy function, on GridNav's own (dict)
    observations: `(params, carry, obs, first, key) -> (action [B], carry)`, no carry (the
    network has no memory). Samples with `split(key, 3)[0]`, apart from the environment's
    `split(key, 3)[2]`."""
    flat = FlattenObservationWrapper(env)
    network = ActorCritic(env.num_actions)

    def policy(params, carry, obs, first, key):
        logits, _ = network.apply(params, flat.flatten(obs))
        action = jnp.argmax(logits, -1) if greedy else jax.random.categorical(jax.random.split(key, 3)[0], logits)
        return action, carry

    return policy


@dataclasses.dataclass(frozen=True)
class Args:
    """PureJaxRL's PPO on quick's frames, tested on the reports' episodes (module docstring)."""

    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    learning_rates: tuple[float, ...] = (2.5e-4, 1e-3)
    """candidates, chosen by the mean validation SR over the seeds"""
    total_timesteps: int = QUICK_FRAMES
    greedy: bool = False
    """also test the argmax policy (on the same episodes)"""
    out: Path | None = None
    """write the results here as JSON (refused if it exists)"""


def _sr(results) -> float:
    return results["overall"]["SR"]


def main(args: Args) -> dict:
    if args.out is not None and args.out.exists():
        raise SystemExit(f"{args.out} exists: pass another --out, or move it away")
    config, schedule = preset("quick", "a3c")
    env, env_params = envs.make_gymnax(
        setup=config.setup, split="train", room_types=config.room_types or None, step_api="done"
    )
    gridnav = env.gridnav
    report = {
        "ppo_config": dict(CONFIG, TOTAL_TIMESTEPS=args.total_timesteps),
        "seeds": list(args.seeds),
        "jax": jax.__version__,
        "device": str(jax.devices()[0]),
        "by_lr": {},
    }
    keys = jnp.stack([selection.run_key(s) for s in args.seeds])
    none = lambda n: None  # noqa: E731  (no carry)
    trained = {}
    for lr in args.learning_rates:
        ppo = dict(CONFIG, LR=lr, TOTAL_TIMESTEPS=args.total_timesteps)
        t0 = time.perf_counter()
        out = jax.block_until_ready(jax.jit(jax.vmap(make_train(ppo, env, env_params)))(keys))
        seconds = time.perf_counter() - t0
        params = out["runner_state"][0].params
        trained[lr] = params
        val = [
            _sr(
                evaluate_policy(
                    make_policy(gridnav),
                    jax.tree.map(lambda x: x[i], params),
                    none,
                    config,
                    "val",
                    selection.validation_key(s),
                    schedule.val_episodes_per_room,
                )
            )
            for i, s in enumerate(args.seeds)
        ]
        report["by_lr"][str(lr)] = {"train_seconds": seconds, "val_sr": val}
        print(
            f"lr {lr:g}: trained {len(args.seeds)} seeds x {num_updates(ppo) * ppo['NUM_ENVS'] * ppo['NUM_STEPS']:,} "
            f"frames in {seconds:.0f} s; validation SR {np.mean(val):.1f} ({', '.join(f'{v:.1f}' for v in val)})",
            flush=True,
        )
    best = max(args.learning_rates, key=lambda lr: np.mean(report["by_lr"][str(lr)]["val_sr"]))
    report["learning_rate"] = best
    for name, greedy in [("sampled", False)] + ([("greedy", True)] if args.greedy else []):
        tests = [
            evaluate_policy(
                make_policy(gridnav, greedy),
                jax.tree.map(lambda x: x[i], trained[best]),
                none,
                config,
                "test",
                selection.test_key(s),
                schedule.test_episodes_per_room,
            )
            for i, s in enumerate(args.seeds)
        ]
        sr = np.array([_sr(t) for t in tests])
        spl = np.array([t["overall"]["SPL"] for t in tests])
        s = stats.summary(sr)
        report[name] = {
            "test_sr": sr.tolist(),
            "test_spl": spl.tolist(),
            "sr": s,
            "spl": stats.summary(spl),
            "tests": tests,
        }
        print(
            f"test ({name}, lr {best:g}): SR {s['mean']:.1f} ± {s['std']:.1f} [{s['ci_low']:.1f}, {s['ci_high']:.1f}], "
            f"SPL {spl.mean():.1f}; seeds {list(args.seeds)}",
            flush=True,
        )
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1, default=float))
    return report


if __name__ == "__main__":
    main(tyro.cli(Args))
