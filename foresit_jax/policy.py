"""The agent step by step: a pure, batched policy function for a user's own loop.

`policy(nets)` is `(acting, carry, obs, first, key) -> (action [B], carry)`, the agent of
`nets` (the a3c base; the maml base's, which adapts inside an episode, is
`foresit_jax.maml.policy`) computing what `foresit_jax.rollout.act_window` computes at
each step (`rollout.agent_step`, then `rollout.advance`), one step per call. Its `step_keys` give the keys that
replay `rollout.rollout`'s episodes exactly (`foresit_jax.evaluate.policy_episodes`).

    step = policy(nets)
    carry = policy_carry(nets, num_lanes)      # a `rollout.AgentCarry`
    action, carry = step(AgentParams(params, w, variance), carry, obs, first, key)
"""

from __future__ import annotations

import dataclasses
from typing import Callable, Optional

import chex
import jax
import jax.numpy as jnp

from foresit_jax import distributions
from foresit_jax.lstm import reset_carry
from foresit_jax.networks import Networks
from foresit_jax.rollout import AgentCarry, AgentParams, advance, agent_carry, agent_step


def lockstep_keys(key: chex.PRNGKey, num_steps: int, num_lanes: int) -> tuple[chex.Array, chex.Array]:
    """The keys `rollout.rollout` gives a window under one parameter set (the a3c base),
    for a step-by-step replay: (the policy's `[T, 2]`, `split(key, T)`; the environment's
    `[T, B, 2]`, `split(split(step key, 3)[2], B)`)."""
    keys = jax.random.split(key, num_steps)
    return keys, jax.vmap(lambda k: jax.random.split(jax.random.split(k, 3)[2], num_lanes))(keys)


@dataclasses.dataclass(frozen=True)
class StepPolicy:
    """A batched policy function, `(acting, carry, obs, first, key) -> (action [B], carry)`
    (call it), with the key schedule that replays `rollout.rollout`'s episodes exactly:
    `step_keys(key, num_steps, num_lanes) -> (the policy's keys [T, ...], the
    environment's [T, B, 2])` (`foresit_jax.evaluate.policy_episodes` reads it)."""

    act: Callable
    step_keys: Callable = lockstep_keys

    def __call__(self, acting, carry, obs, first, key):
        return self.act(acting, carry, obs, first, key)


def policy_carry(nets: Networks, num_lanes: int, acting: Optional[AgentParams] = None, obs=None) -> AgentCarry:
    """The carry before any step (`first` at the first step resets it anyway): the agent's
    carry of acting (`rollout.agent_carry`: zeros, and success trackers the policy never
    reads, since its noise variance is given). (`acting` and `obs` are the maml base's,
    `foresit_jax.maml.policy_carry`; unused here.)"""
    _check_base(nets, "policy_carry")
    return agent_carry(nets, num_lanes)


def _check_base(nets: Networks, name: str) -> None:
    if nets.method.base_piece.adapts_in_episode:
        raise ValueError(
            f"method {nets.method.name!r} adapts its parameters inside each episode (the maml base): "
            f"use foresit_jax.maml.{name}, whose carry holds each lane's adapted parameters"
        )


def with_noise(acting: AgentParams, lanes: int) -> AgentParams:
    """`acting` with its noise variance broadcast to `[lanes]` (it must be set: evaluation's)."""
    if acting.noise_variance is None:
        raise ValueError("policy: give AgentParams.noise_variance, the evaluation's fixed variance")
    variance = jnp.broadcast_to(jnp.asarray(acting.noise_variance, jnp.float32), (lanes,))
    return acting._replace(noise_variance=variance)


def reset(carry: AgentCarry, first: chex.Array) -> AgentCarry:
    """The carry as a step sees it: zeroed where `first` begins an episode."""
    probs = jnp.where(first[:, None], 0.0, carry.prev_probs)
    return carry._replace(
        lstm=reset_carry(first, carry.lstm), prev_probs=probs, episode_step=jnp.where(first, 0, carry.episode_step)
    )


def policy_step(nets: Networks, acting: AgentParams, kernels, carry: AgentCarry, obs, key, greedy: bool):
    """One step of the agent on a reset carry: (action [B], the next carry). `key` is split
    in 3 as acting splits it: i_tau's noise, the action's sample, the environment's."""
    k_imag, k_act, _ = jax.random.split(key, 3)
    out = agent_step(nets, acting, kernels, carry, obs, k_imag, None)
    action = distributions.greedy(out.logits) if greedy else distributions.sample(k_act, out.logits)
    return action, advance(nets, carry, out)


def policy(nets: Networks, greedy: bool = False) -> StepPolicy:
    """The agent as a pure, batched policy function:
    `(acting, carry, obs, first, key) -> (action [B], carry)`.

    acting: `AgentParams` with the noise variance `[B]` (or `[]`) set (evaluation's);
    carry: `policy_carry(nets, B)` to start; obs: the environment's observations, leaves
    `[B, ...]` (for the privileged `oracle` and the cues, from an environment wrapped by
    `rollout.acting_env`); first: `[B]` bool, the step begins an episode (the carry is
    reset there); key: the step's key, split in 3 as acting splits it: i_tau's noise, the
    action's sample, and (unused here) the environment's."""
    _check_base(nets, "policy")

    def act(acting: AgentParams, carry: AgentCarry, obs, first: chex.Array, key: chex.PRNGKey):
        acting = with_noise(acting, first.shape[0])
        kernels = nets.lstm_kernels(acting.params)
        return policy_step(nets, acting, kernels, reset(carry, first), obs, key, greedy)

    return StepPolicy(act)
