"""Evaluation as in Section 5: SR, SPL, and both over episodes with L^g >= 5, per room type.

SPL = (1/N) sum_i s_i L^g_i / max(L_i, L^g_i), where L^g is the oracle's shortest number of
actions to success (Done included) and L the number of actions taken.  Episodes use the
evaluation time limits (100 steps, 200 in living rooms); by default 250 per room type.
Actions are sampled from the policy, as SAVN does, except for methods on ORG's encoder, which
take the argmax as ORG's own evaluation does (`Method.greedy_evaluation`); ``greedy`` overrides.
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple

import chex
import jax
import jax.numpy as jnp
import numpy as np

from foresit_jax import imagination
from foresit_jax.agent import Agent, episode_stats
from foresit_jax.config import Config

ROOM_TYPES = ("kitchen", "living_room", "bedroom", "bathroom")
LONG_EPISODE = 5  # the L >= 5 bucket of Table 1


class AgentParams(NamedTuple):
    """What acting needs: theta/omega, w, and the imagination-noise variance."""

    params: Any
    imagination_params: Any
    noise_variance: chex.Array  # [] sigma^2 used at evaluation


def agent_params(state, sigma2_max: float) -> AgentParams:
    """From a training RunnerState.  The evaluation noise variance is the lanes' mean of
    Eq. 7 at the end of training: the imagination the policy was trained with."""
    rho = jax.vmap(imagination.success_rate)(state.actor.tracker)  # [B]
    variance = jnp.mean(imagination.noise_variance(rho, sigma2_max))
    return AgentParams(state.params, state.imagination_params, variance)


def summarize(success, spl, optimal_length) -> dict[str, float]:
    """SR, SPL, SR>=5, SPL>=5 (in %) and counts from per-episode numpy arrays."""
    success = np.asarray(success, np.float64)
    spl = np.asarray(spl, np.float64)
    long = np.asarray(optimal_length) >= LONG_EPISODE
    mean = lambda x, m: float(100.0 * x[m].mean()) if m.any() else float("nan")  # noqa: E731
    every = np.ones_like(long)
    return {
        "SR": mean(success, every),
        "SPL": mean(spl, every),
        "SR>=5": mean(success, long),
        "SPL>=5": mean(spl, long),
        "episodes": int(len(success)),
        "episodes>=5": int(long.sum()),
    }


@functools.lru_cache(maxsize=8)
def _setup_env(setup: str):
    import envs

    return envs.GridNav(setup=setup)


@functools.lru_cache(maxsize=32)
def _room_env(setup: str, split: str, room: str):
    """One env object per setup (so the jitted rollouts are shared by every room type and
    split of the same episode length) and the params of one room type of a split."""
    env = _setup_env(setup)
    return env, env.make_params(split, room_types=(room,), training=False)


def evaluate(
    agent_params: AgentParams,
    config: Config,
    split: str = "test",
    key: chex.PRNGKey | None = None,
    episodes_per_room: int = 250,
    greedy: bool | None = None,
    room_types: tuple[str, ...] | None = None,
) -> dict[str, dict[str, float]]:
    """Run `episodes_per_room` episodes in each room type of `split` ("val" or "test").

    Returns {"overall": metrics, "kitchen": metrics, ...} with metrics from `summarize`.
    """
    if split not in ("train", "val", "test"):
        raise ValueError(f"split must be 'val' or 'test' (or 'train'), got {split!r}")
    if episodes_per_room < 1:
        raise ValueError(f"episodes_per_room must be >= 1, got {episodes_per_room}")
    key = jax.random.PRNGKey(0) if key is None else key
    greedy = config.pieces.greedy_evaluation if greedy is None else bool(greedy)
    rooms = tuple(room_types or config.room_types or ROOM_TYPES)
    results, pooled = {}, []
    for room, k in zip(rooms, jax.random.split(key, len(rooms))):
        env, env_params = _room_env(config.setup, split, room)
        num_steps = int(jnp.max(env_params.max_steps))
        sigma2 = jnp.full((episodes_per_room,), agent_params.noise_variance, jnp.float32)
        stats = _rollout_stats(config, env, num_steps, greedy)(
            agent_params.params, agent_params.imagination_params, env_params, k, sigma2
        )
        stats = jax.tree.map(np.asarray, stats)
        results[room] = summarize(stats.success, stats.spl, stats.optimal_length)
        pooled.append(stats)
    results["overall"] = summarize(*(np.concatenate([getattr(s, f) for s in pooled]) for f in ("success", "spl", "optimal_length")))
    return results


def evaluate_random_policy(
    config: Config, split: str = "test", key: chex.PRNGKey | None = None, episodes_per_room: int = 250
) -> dict[str, dict[str, float]]:
    """The uniformly random policy on the same room types and episodes count: the
    reference a trained agent must beat."""
    key = jax.random.PRNGKey(0) if key is None else key
    rooms = tuple(config.room_types or ROOM_TYPES)
    results, pooled = {}, []
    for room, k in zip(rooms, jax.random.split(key, len(rooms))):
        env, env_params = _room_env(config.setup, split, room)
        num_steps = int(jnp.max(env_params.max_steps))
        stats = jax.tree.map(np.asarray, _random_stats(env, num_steps, episodes_per_room)(env_params, k))
        results[room] = summarize(*stats)
        pooled.append(stats)
    results["overall"] = summarize(*(np.concatenate(parts) for parts in zip(*pooled)))
    return results


@functools.lru_cache(maxsize=32)
def _random_stats(env, num_steps: int, episodes: int):
    def run(env_params, key):
        k_reset, k_steps = jax.random.split(key)
        _, state = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(k_reset, episodes), env_params)
        optimal = state.optimal_length  # [N] L^g of each episode

        def step(carry, key):
            state, alive = carry
            k_act, k_env = jax.random.split(key)
            action = jax.random.randint(k_act, (episodes,), 0, env.num_actions)
            _, state, _, term, trunc, info = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
                jax.random.split(k_env, episodes), state, action, env_params
            )
            return (state, alive & ~(term | trunc)), (info["success"] & alive, alive)

        _, (success, valid) = jax.lax.scan(step, (state, jnp.ones(episodes, bool)), jax.random.split(k_steps, num_steps))
        success = success.any(0)
        length = valid.sum(0)
        spl = success * optimal / jnp.maximum(length, optimal)
        return success, spl, optimal

    return jax.jit(run)


@functools.lru_cache(maxsize=32)
def _rollout_stats(config: Config, env, num_steps: int, greedy: bool):
    agent = Agent(config)

    def run(params, w_params, env_params, key, sigma2):
        traj = agent.rollout(params, w_params, env, env_params, key, sigma2, num_steps, greedy)
        return episode_stats(traj)

    return jax.jit(run)
