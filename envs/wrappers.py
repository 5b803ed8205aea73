"""Wrappers: the five-value legacy step API and episode statistics (gymnax style)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct


class Wrapper:
    """Forwards everything it does not override to the wrapped environment."""

    def __init__(self, env):
        self._env = env

    def __getattr__(self, name):
        return getattr(self._env, name)


class LegacyStepAPIWrapper(Wrapper):
    """``step`` returns five values ``obs, state, reward, done, info`` with
    ``done = terminated | truncated``; ``info`` keeps both flags."""

    def step(self, key, state, action, params=None):
        obs, state, reward, terminated, truncated, info = self._env.step(key, state, action, params)
        return obs, state, reward, terminated | truncated, info


@struct.dataclass
class LogEnvState:
    env_state: object
    episode_return: jax.Array  # float32 [] running return of the current episode
    episode_length: jax.Array  # int32 [] running length of the current episode
    returned_episode_return: jax.Array  # float32 [] return of the last finished episode
    returned_episode_length: jax.Array  # int32 []
    returned_episode_success: jax.Array  # bool []
    returned_episode_spl: jax.Array  # float32 [] success * L_opt / max(L, L_opt)


class LogWrapper(Wrapper):
    """Keeps the statistics of the last finished episode in the state and in ``info``:
    ``returned_episode_return``, ``..._length``, ``..._success``, ``..._spl`` and
    ``returned_episode`` (whether an episode ended at this step).  Works over the
    six-value step of GridNav."""

    def reset(self, key, params=None):
        obs, env_state = self._env.reset(key, params)
        zero_f, zero_i = jnp.zeros((), jnp.float32), jnp.zeros((), jnp.int32)
        return obs, LogEnvState(env_state, zero_f, zero_i, zero_f, zero_i, jnp.zeros((), bool), zero_f)

    def step(self, key, state, action, params=None):
        obs, env_state, reward, terminated, truncated, info = self._env.step(key, state.env_state, action, params)
        done = terminated | truncated
        ret = state.episode_return + reward
        length = state.episode_length + 1
        spl = info["success"] * info["optimal_length"] / jnp.maximum(length, info["optimal_length"])
        state = LogEnvState(
            env_state=env_state,
            episode_return=jnp.where(done, 0.0, ret),
            episode_length=jnp.where(done, 0, length),
            returned_episode_return=jnp.where(done, ret, state.returned_episode_return),
            returned_episode_length=jnp.where(done, length, state.returned_episode_length),
            returned_episode_success=jnp.where(done, info["success"], state.returned_episode_success),
            returned_episode_spl=jnp.where(done, spl, state.returned_episode_spl).astype(jnp.float32),
        )
        info = dict(info)
        info["returned_episode"] = done
        info["returned_episode_return"] = state.returned_episode_return
        info["returned_episode_length"] = state.returned_episode_length
        info["returned_episode_success"] = state.returned_episode_success
        info["returned_episode_spl"] = state.returned_episode_spl
        return obs, state, reward, terminated, truncated, info
