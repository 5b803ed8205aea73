"""Synchronous batched actor-critic standing in for A3C (PureJaxRL shape).

One update = every lane resets and runs one episode to Done or the time limit (a padded,
masked rollout of `num_steps`), then one gradient step on the mean A3C loss (Eq. 8-9);
then the ForeSIT bookkeeping of Algorithm 1: successful lanes add (s_0, g_tau, ŝ_tau) to
their buffers, every lane records its outcome (the moving success rate rho that sets the
imagination noise), and full buffers train the shared f_w and are emptied.

    trainer = make_trainer(config)
    state = trainer.init(key)
    state, metrics = trainer.run(state, trainer.env_params, num_updates)  # jittable
    train = make_train(config)                      # PureJaxRL: one jittable function
    final_state, metrics = jax.jit(jax.vmap(train))(keys)    # a seed sweep in one program

Metrics are reduced per update inside the scan (scalars per update, nothing grows with
the number of environment steps).
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import chex
import jax
import jax.numpy as jnp
import optax

from foresit_jax import imagination, losses
from foresit_jax.agent import Agent, Trajectory, episode_stats
from foresit_jax.config import Config
from foresit_jax.networks import last_step_attention, select_subgoal


class RunnerState(NamedTuple):
    """Everything a training run carries from one update to the next."""

    params: Any  # theta and omega (encoder, policy, critic)
    opt_state: Any  # Adam state of params
    imagination_params: Any  # w, the shared f_w
    buffers: imagination.ReplayBuffer  # per lane, leaves [B, M, ...]
    trackers: imagination.SuccessTracker  # per lane, leaves [B, window]
    key: chex.PRNGKey
    update: chex.Array  # int32 [] updates done


def make_env(config: Config, split: str = "train", room_types=None, training: bool | None = None):
    """The environment of a config (foresit_jax sees envs only through its public API)."""
    import envs

    rooms = room_types if room_types is not None else (config.room_types or None)
    return envs.make("GridNav-v0", setup=config.setup, split=split, room_types=rooms, training=training)


GRADIENTS: tuple[str, ...] = ("replay", "through_rollout")


class Trainer:
    """The pure functions of one training run of `config` (see module docstring).

    gradient: how the loss's gradient is computed; both give the gradient of the same
    loss (equal up to float rounding: the sums run in a different order).
      'replay' (default): act without gradients, then recompute s_t and the logits from
        the recorded inputs, differentiably (`Agent.replay`: batched, padding skipped).
      'through_rollout': differentiate through the acting scan, environment steps
        included (the reference; several times slower at the paper's sizes on a CPU).
    """

    def __init__(self, config: Config, env=None, env_params=None, gradient: str = "replay"):
        if gradient not in GRADIENTS:
            raise ValueError(f"gradient must be one of {GRADIENTS}, got {gradient!r}")
        if env is None:
            env, env_params = make_env(config)
        limit = int(jnp.max(env_params.max_steps))
        if config.num_steps < limit:
            raise ValueError(
                f"num_steps ({config.num_steps}) must be at least the environment's training "
                f"time limit ({limit}): one update runs whole episodes"
            )
        self.config = config
        self.gradient = gradient
        self.env = env
        self.env_params = env_params
        self.agent = Agent(config)
        self.optimizer = optax.chain(
            optax.clip_by_global_norm(config.max_grad_norm), optax.adam(config.learning_rate)
        )
        self.imagination_optimizer = imagination.make_imagination_optimizer(
            config.imagination_optimizer, config.imagination_lr
        )

    # ------------------------------------------------------------------ state
    def init(self, key: chex.PRNGKey) -> RunnerState:
        cfg = self.config
        k_obs, k_params, key = jax.random.split(key, 3)
        obs, _ = self.env.reset(k_obs, self.env_params)
        params, w_params = self.agent.init(k_params, obs)
        goal_size = obs["target"].shape[-1]
        lanes = lambda x: jnp.broadcast_to(x, (cfg.num_lanes,) + x.shape)  # noqa: E731
        buffers = jax.tree.map(lanes, imagination.buffer_init(cfg.buffer_size, cfg.hidden_size, goal_size))
        trackers = jax.tree.map(lanes, imagination.tracker_init(cfg.success_window))
        return RunnerState(
            params, self.optimizer.init(params), w_params, buffers, trackers, key, jnp.zeros((), jnp.int32)
        )

    # ------------------------------------------------------------------ one update
    def loss(self, params, w_params, env_params, key, sigma2):
        """Roll out one episode per lane with `params` and return the A3C loss (Eq. 8-9)."""
        cfg = self.config
        if self.gradient == "replay":
            acting = jax.lax.stop_gradient(params)
            traj = self.agent.rollout(acting, w_params, self.env, env_params, key, sigma2, cfg.num_steps, record_inputs=True)
            states, logits = self.agent.replay(params, traj)
            traj = traj._replace(states=states, logits=logits, inputs=None)
        else:
            traj = self.agent.rollout(params, w_params, self.env, env_params, key, sigma2, cfg.num_steps)
        critic = self.agent.critic(params, traj)
        bootstrap = jnp.zeros_like(critic.value[0])  # whole episodes: nothing to bootstrap
        advantage, returns = losses.advantages_and_returns(
            traj.rewards, critic.value, traj.terminated, traj.truncated, traj.valid,
            bootstrap, cfg.gamma, cfg.gae_lambda,
        )  # fmt: skip
        loss, metrics = losses.a3c_loss(
            traj.logits, traj.actions, critic.value, advantage, returns, traj.valid,
            cfg.entropy_coef, cfg.value_coef,
        )  # fmt: skip
        return loss, (traj, critic.alpha, metrics)

    def update(self, state: RunnerState, env_params) -> tuple[RunnerState, dict]:
        cfg, flags = self.config, self.agent.flags
        key, k_roll = jax.random.split(state.key)
        rho = jax.vmap(imagination.success_rate)(state.trackers)  # [B]
        sigma2 = imagination.noise_variance(rho, cfg.sigma2_max)  # [B]
        grad_fn = jax.value_and_grad(self.loss, has_aux=True)
        (loss, (traj, alpha, metrics)), grads = grad_fn(state.params, state.imagination_params, env_params, k_roll, sigma2)
        updates, opt_state = self.optimizer.update(grads, state.opt_state, state.params)
        params = optax.apply_updates(state.params, updates)

        stats = episode_stats(traj)
        trackers = jax.vmap(imagination.tracker_update)(state.trackers, stats.success, stats.ended)
        buffers, w_params = state.buffers, state.imagination_params
        metrics = dict(metrics)
        if flags.trains_imagination:
            subgoal = self.subgoals(traj, alpha)  # [B, H]
            item = (traj.states[0], traj.target, subgoal)
            buffers = jax.vmap(imagination.buffer_add)(buffers, *item, stats.success)
            w_params, buffers, imag_metrics = imagination.train_full_buffers(
                w_params, buffers, self.agent.imagine, self.imagination_optimizer, cfg.imagination_epochs
            )
            metrics.update(imag_metrics)
        metrics.update(
            {
                "charts/success_rate": jnp.mean(stats.success.astype(jnp.float32)),
                "charts/spl": jnp.mean(stats.spl),
                "charts/episode_length": jnp.mean(stats.length.astype(jnp.float32)),
                "charts/optimal_length": jnp.mean(stats.optimal_length.astype(jnp.float32)),
                "charts/padded_fraction": 1.0 - jnp.mean(traj.valid.astype(jnp.float32)),
                "charts/noise_variance": jnp.mean(sigma2),
                "charts/moving_success_rate": jnp.mean(rho),
                "losses/grad_norm": optax.tree.norm(grads),
            }
        )
        new_state = RunnerState(params, opt_state, w_params, buffers, trackers, key, state.update + 1)
        return new_state, metrics

    def subgoals(self, traj: Trajectory, alpha) -> chex.Array:
        """ŝ_tau per lane `[B, H]`: the state with the largest attention of the episode's
        last step (ForeSIT) or the attention-weighted average (`att` ablation)."""
        states = jnp.swapaxes(traj.states, 0, 1)  # [B, T, H]
        alpha_last = last_step_attention(alpha, jnp.swapaxes(traj.valid, 0, 1))  # [B, T]
        return select_subgoal(states, alpha_last, self.agent.flags.subgoal_mode)

    def run(self, state: RunnerState, env_params, num_updates: int) -> tuple[RunnerState, dict]:
        """`num_updates` updates in a `lax.scan`; metrics stacked `[num_updates]`."""
        return jax.lax.scan(lambda s, _: self.update(s, env_params), state, None, length=num_updates)

    def train(self, key: chex.PRNGKey) -> tuple[RunnerState, dict]:
        """The whole run in one jittable function: init, then `config.num_updates` updates."""
        return self.run(self.init(key), self.env_params, self.config.num_updates)


def make_trainer(config: Config, env=None, env_params=None, gradient: str = "replay") -> Trainer:
    return Trainer(config, env, env_params, gradient)


def make_train(config: Config, env=None, env_params=None) -> Callable[[chex.PRNGKey], tuple[RunnerState, dict]]:
    """PureJaxRL's entry point: `train(key) -> (final RunnerState, metrics [num_updates])`."""
    return make_trainer(config, env, env_params).train
