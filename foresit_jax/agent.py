"""The acting agent: one rollout function shared by training and evaluation.

An `Agent` ties the networks of a `Config` together (encoder + policy + critic under one
parameter tree, theta and omega; f_w under its own tree, w) and runs batched episodes
against any environment with the GridNav API (``reset``/``step`` on a batch via vmap).
Training differentiates through `rollout` (the environment's outputs carry no gradient);
evaluation calls the same function without gradients.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import chex
import jax
import jax.numpy as jnp

from foresit_jax import distributions, imagination
from foresit_jax.config import Config
from foresit_jax.networks import ActorCritic, ImaginationNet, initial_carry


class Trajectory(NamedTuple):
    """One padded episode per lane, time-major."""

    states: chex.Array  # [T, B, H] s_t (LSTM hidden state)
    logits: chex.Array  # [T, B, A]
    actions: chex.Array  # [T, B] int32
    rewards: chex.Array  # [T, B]
    terminated: chex.Array  # [T, B] bool, Done taken
    truncated: chex.Array  # [T, B] bool, time limit reached
    valid: chex.Array  # [T, B] bool, step belongs to the lane's first episode
    success: chex.Array  # [T, B] bool, successful Done at this step
    target: chex.Array  # [B, D] g_tau of the episode
    optimal_length: chex.Array  # [B] int32 L^g of the episode
    room_type: chex.Array  # [B] int32


class EpisodeStats(NamedTuple):
    success: chex.Array  # [B] bool
    length: chex.Array  # [B] int32 actions taken, Done included
    optimal_length: chex.Array  # [B] int32
    spl: chex.Array  # [B] float32 success * L^g / max(L, L^g)
    ended: chex.Array  # [B] bool, the episode ended inside the rollout
    room_type: chex.Array  # [B] int32


def episode_stats(traj: Trajectory) -> EpisodeStats:
    valid = traj.valid
    length = jnp.sum(valid.astype(jnp.int32), axis=0)
    success = jnp.any(traj.success & valid, axis=0)
    ended = jnp.any((traj.terminated | traj.truncated) & valid, axis=0)
    opt = traj.optimal_length
    spl = success * opt / jnp.maximum(length, opt).astype(jnp.float32)
    return EpisodeStats(success, length, opt, spl.astype(jnp.float32), ended, traj.room_type)


class Agent:
    """Networks and acting for one method (a `Config`)."""

    def __init__(self, config: Config):
        self.config = config
        flags = config.flags
        self.flags = flags
        self.model = ActorCritic(
            num_actions=config.num_actions,
            hidden_size=config.hidden_size,
            use_imagination=flags.uses_imagination,
            attention_critic=flags.attention_critic,
            attention_size=config.attention_size,
            value_hidden=config.value_hidden,
        )
        self.imagination_net = ImaginationNet(config.imagination_layer_sizes)

    # ------------------------------------------------------------------ init
    def init(self, key: chex.PRNGKey, obs: dict) -> tuple[Any, Any]:
        """(theta/omega params, f_w params) from one unbatched observation."""
        k_model, k_imag = jax.random.split(key)
        hidden = self.config.hidden_size
        carry = initial_carry((), hidden)
        probs = jnp.zeros((self.config.num_actions,), jnp.float32)
        imagined = jnp.zeros((hidden,), jnp.float32) if self.flags.uses_imagination else None
        params = self.model.init(k_model, carry, obs, probs, imagined)
        w_params = self.imagination_net.init(k_imag, jnp.zeros((hidden,)), obs["target"])
        return params, w_params

    def imagine(self, w_params, s_0: chex.Array, goal: chex.Array) -> chex.Array:
        """f_w([s_0 : g_tau]) `[..., H]`."""
        return self.imagination_net.apply(w_params, s_0, goal)

    def _imagined_subgoal(self, w_params, s_t, goal, key, sigma2):
        """i_tau for the policy (stop-gradient: the policy loss never trains f_w or,
        through it, s_0).  ForeSIT: f_w + N(0, sigma2); rnd: tanh(N(0, 0.5))."""
        if self.flags.imagination == "random":
            return imagination.random_imagination(key, s_t.shape, self.config.rnd_variance)
        imagined = self.imagine(w_params, jax.lax.stop_gradient(s_t), goal)
        return jax.lax.stop_gradient(imagination.add_imagination_noise(key, imagined, sigma2))

    # ------------------------------------------------------------------ acting
    def rollout(self, params, w_params, env, env_params, key, sigma2, num_steps: int, greedy: bool = False):
        """Reset every lane and run its episode for `num_steps` steps (padded, masked).

        sigma2: `[B]` imagination-noise variance per lane; its length sets the batch.
        Returns a `Trajectory`.  Steps after a lane's episode ended are padding
        (valid=False): the environment auto-resets, and what follows is ignored.
        """
        num_lanes = sigma2.shape[0]
        hidden = self.config.hidden_size
        k_reset, k_steps = jax.random.split(key)
        obs, env_state = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(k_reset, num_lanes), env_params)
        goal = obs["target"]  # [B, D]
        optimal_length = env_state.optimal_length
        room_type = env_state.room_type
        model = self.model
        flags, interval = self.flags, self.config.int_interval

        def step(carry, inputs):
            t, key = inputs
            lstm, prev_probs, imagined, env_state, obs, alive = carry
            k_imag, k_act, k_env = jax.random.split(key, 3)
            lstm, s_t = model.apply(params, lstm, obs, prev_probs, method=ActorCritic.encode)
            if flags.uses_imagination:
                renew = t == 0
                if flags.reimagine_every_k:
                    renew = t % interval == 0
                imagined = jax.lax.cond(
                    renew,
                    lambda: self._imagined_subgoal(w_params, s_t, goal, k_imag, sigma2),
                    lambda: imagined,
                )
            policy_input = imagined if flags.uses_imagination else None
            logits = model.apply(params, s_t, policy_input, method=ActorCritic.policy_logits)
            action = distributions.greedy(logits) if greedy else distributions.sample(k_act, logits)
            obs, env_state, reward, term, trunc, info = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
                jax.random.split(k_env, num_lanes), env_state, action, env_params
            )
            out = (s_t, logits, action, reward, term, trunc, alive, info["success"] & alive)
            probs = jax.lax.stop_gradient(distributions.probs(logits))
            return (lstm, probs, imagined, env_state, obs, alive & ~(term | trunc)), out

        init = (
            initial_carry((num_lanes,), hidden),
            jnp.zeros((num_lanes, self.config.num_actions), jnp.float32),
            jnp.zeros((num_lanes, hidden), jnp.float32),
            env_state,
            obs,
            jnp.ones((num_lanes,), bool),
        )
        steps = (jnp.arange(num_steps), jax.random.split(k_steps, num_steps))
        _, out = jax.lax.scan(step, init, steps)
        states, logits, actions, rewards, term, trunc, valid, success = out
        return Trajectory(states, logits, actions, rewards, term, trunc, valid, success, goal,
                          optimal_length, room_type)  # fmt: skip

    def critic(self, params, traj: Trajectory):
        """Critic over each lane's episode: CriticOutput with value `[T, B]`, alpha
        `[B, T, T]` (None for the plain critic)."""
        out = self.model.apply(
            params, jnp.swapaxes(traj.states, 0, 1), jnp.swapaxes(traj.valid, 0, 1),
            method=ActorCritic.critic,
        )  # fmt: skip
        return out._replace(value=jnp.swapaxes(out.value, 0, 1))
