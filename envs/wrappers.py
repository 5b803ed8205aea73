"""Wrappers (gymnax style): a flat observation vector, the five-value legacy step API,
episode statistics, and (privileged, for diagnostics) each episode's goal view.

A PureJaxRL-style stack over GridNav (``envs.make_gymnax`` gives the first two layers in
one call, with gymnax's space classes)::

    env, params = envs.make("GridNav-v0")
    env = LogWrapper(LegacyStepAPIWrapper(FlattenObservationWrapper(env)))
    # env.observation_space(params).shape == (N,), env.action_space(params).n == 6
    # obs, state, reward, done, info = env.step(key, state, action, params)

``FlattenObservationWrapper`` and ``LogWrapper`` (ours) take the six-value step of GridNav
and a five-value one, so PureJaxRL's own ``LogWrapper`` can go over
``LegacyStepAPIWrapper(FlattenObservationWrapper(env))`` too.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from envs import spaces
from envs.metrics import spl as spl_term


class Wrapper:
    """Forwards everything it does not override to the wrapped environment."""

    def __init__(self, env):
        self._env = env

    def _params(self, params):
        """`params`, or the wrapped environment's default params where None (gymnax's rule)."""
        return self._env.default_params if params is None else params

    def __getattr__(self, name):
        # Python calls this only for names not found on the wrapper. `copy`, `pickle` and
        # `copy.deepcopy` build a new wrapper without `__init__` and look up dunder names
        # (`__setstate__`, `__deepcopy__`, ...) on it before `_env` exists: forwarding those,
        # or `_env` itself, would recurse forever. They are the wrapper's own, never the env's.
        if name == "_env" or (name.startswith("__") and name.endswith("__")):
            raise AttributeError(name)
        return getattr(self._env, name)


class FlattenObservationWrapper(Wrapper):
    """Observations as one flat float32 vector, with a ``Box`` observation space of that size.

    A dict observation is flattened key by key in the order of ``KEY_ORDER`` (GridNav:
    ``view`` [3, W, C], then ``target``, then, in the org setup, ``detections``
    [22, 7]), any other keys after them in sorted order; each part row-major (C order)
    and cast to float32.  ``unflatten`` inverts it; ``layout`` gives each part's slice.
    A Box (array) observation is simply raveled.  The space's ``low``/``high`` are the
    parts' bounds, broadcast and concatenated (float32 [N]).

    ``info["final_observation"]``, when present, is flattened the same way.  ``step`` may
    return six values (GridNav) or five (``LegacyStepAPIWrapper``): the observation is the
    first value, ``info`` the last.  This stands in for gymnax's ``FlattenObservationWrapper``,
    which accepts only gymnax's own ``Box`` (see ``envs.spaces``).
    """

    KEY_ORDER = ("view", "target", "detections")

    def layout(self, params=None) -> tuple[tuple[str, tuple[int, ...], int, int], ...]:
        """(key, shape, start, stop) of each part of the flat vector, in order (dict
        observations only)."""
        space = self._env.observation_space(params)
        if not isinstance(space, spaces.Dict):
            raise TypeError(f"layout needs a Dict observation space, got {space!r}")
        keys = [k for k in self.KEY_ORDER if k in space.spaces]
        keys += sorted(k for k in space.spaces if k not in self.KEY_ORDER)
        parts, start = [], 0
        for key in keys:
            shape = tuple(space.spaces[key].shape)
            size = int(np.prod(shape, dtype=np.int64))
            parts.append((key, shape, start, start + size))
            start += size
        return tuple(parts)

    def observation_space(self, params=None) -> spaces.Box:
        space = self._env.observation_space(params)
        if not isinstance(space, spaces.Dict):
            size = int(np.prod(space.shape, dtype=np.int64))
            bound = lambda b: np.broadcast_to(np.asarray(b, np.float32), space.shape).reshape(size)  # noqa: E731
            return spaces.Box(bound(space.low), bound(space.high), (size,), jnp.float32)
        lows, highs = [], []
        for key, shape, start, stop in self.layout(params):
            sub = space.spaces[key]
            lows.append(np.broadcast_to(np.asarray(sub.low, np.float32), shape).reshape(-1))
            highs.append(np.broadcast_to(np.asarray(sub.high, np.float32), shape).reshape(-1))
        low, high = np.concatenate(lows), np.concatenate(highs)
        return spaces.Box(low, high, low.shape, jnp.float32)

    def flatten(self, obs, params=None) -> jax.Array:
        """float32 [..., N] from an observation of the wrapped env (leading batch axes kept)."""
        space = self._env.observation_space(params)
        if not isinstance(space, spaces.Dict):
            x = jnp.asarray(obs, jnp.float32)
            return x.reshape(x.shape[: x.ndim - len(space.shape)] + (-1,))
        parts = []
        for key, shape, _, _ in self.layout(params):
            x = jnp.asarray(obs[key], jnp.float32)
            parts.append(x.reshape(x.shape[: x.ndim - len(shape)] + (-1,)))
        return jnp.concatenate(parts, -1)

    def unflatten(self, flat, params=None) -> dict:
        """The dict observation (float32 parts) from a flat vector [..., N]."""
        flat = jnp.asarray(flat)
        return {key: flat[..., a:b].reshape(flat.shape[:-1] + shape) for key, shape, a, b in self.layout(params)}

    def reset(self, key, params=None):
        obs, state = self._env.reset(key, params)
        return self.flatten(obs, params), state

    def step(self, key, state, action, params=None):
        obs, *rest, info = self._env.step(key, state, action, params)
        if "final_observation" in info:
            info = dict(info)
            info["final_observation"] = self.flatten(info["final_observation"], params)
        return (self.flatten(obs, params), *rest, info)


class LegacyStepAPIWrapper(Wrapper):
    """``step`` returns five values ``obs, state, reward, done, info`` with
    ``done = terminated | truncated``; ``info`` keeps both flags."""

    def step(self, key, state, action, params=None):
        obs, state, reward, terminated, truncated, info = self._env.step(key, state, action, params)
        return obs, state, reward, terminated | truncated, info


@struct.dataclass
class LogEnvState:
    """PureJaxRL's / gymnax's ``LogEnvState`` fields, plus the last episode's success and SPL."""

    env_state: object
    episode_returns: jax.Array  # float32 [] running return of the current episode
    episode_lengths: jax.Array  # int32 [] running length of the current episode
    returned_episode_returns: jax.Array  # float32 [] return of the last finished episode
    returned_episode_lengths: jax.Array  # int32 []
    returned_episode_success: jax.Array  # bool []
    returned_episode_spl: jax.Array  # float32 [] envs.metrics.spl: success * L_opt / max(L, L_opt)
    timestep: jax.Array  # int32 [] steps taken since reset (across episodes), the last one included


class LogWrapper(Wrapper):
    """Keeps the statistics of the last finished episode in the state and in ``info``,
    under PureJaxRL's and gymnax's names: ``returned_episode_returns``,
    ``returned_episode_lengths``, ``returned_episode`` (whether an episode ended at this
    step) and ``timestep`` (steps since ``reset``, this one included, as PureJaxRL counts),
    plus ``returned_episode_success`` and ``returned_episode_spl`` (``envs.metrics.spl`` of
    the episode).  Works over a six-value step (GridNav) or a five-value one
    (``envs.make_gymnax(step_api="done")``), and returns the same number of values; the
    wrapped env's ``info`` must carry ``success`` and ``optimal_length``, as GridNav's does."""

    def reset(self, key, params=None):
        obs, env_state = self._env.reset(key, params)
        zero_f, zero_i = jnp.zeros((), jnp.float32), jnp.zeros((), jnp.int32)
        return obs, LogEnvState(env_state, zero_f, zero_i, zero_f, zero_i, jnp.zeros((), bool), zero_f, zero_i)

    def step(self, key, state, action, params=None):
        obs, env_state, reward, *flags, info = self._env.step(key, state.env_state, action, params)
        done = flags[0] | flags[1] if len(flags) == 2 else flags[0]
        ret = state.episode_returns + reward
        length = state.episode_lengths + 1
        spl = spl_term(info["success"], length, info["optimal_length"])
        state = LogEnvState(
            env_state=env_state,
            episode_returns=jnp.where(done, 0.0, ret),
            episode_lengths=jnp.where(done, 0, length),
            returned_episode_returns=jnp.where(done, ret, state.returned_episode_returns),
            returned_episode_lengths=jnp.where(done, length, state.returned_episode_lengths),
            returned_episode_success=jnp.where(done, info["success"], state.returned_episode_success),
            returned_episode_spl=jnp.where(done, spl, state.returned_episode_spl).astype(jnp.float32),
            timestep=state.timestep + 1,
        )
        info = dict(info)
        info["returned_episode"] = done
        info["returned_episode_returns"] = state.returned_episode_returns
        info["returned_episode_lengths"] = state.returned_episode_lengths
        info["returned_episode_success"] = state.returned_episode_success
        info["returned_episode_spl"] = state.returned_episode_spl
        info["timestep"] = state.timestep
        return (obs, state, reward, *flags, info)


@struct.dataclass
class GoalViewState:
    """The wrapped env's state and the running episode's goal observation (its parts as
    ``GoalViewWrapper.GOAL_KEYS`` names them)."""

    env_state: object
    goal: dict


class GoalViewWrapper(Wrapper):
    """Privileged: every observation also carries its episode's *goal view*, the view at the
    end of the oracle's shortest path from the episode's start (the pose where Done
    succeeds): ``obs["goal_view"]`` (and ``obs["goal_detections"]`` in the org setup).

    Built from the wrapped env's public API only: from the start, ``optimal_action`` then
    ``step_env`` until ``target_in_view``, then ``get_obs``. The path is walked once per
    episode, at ``reset`` and where ``step`` auto-resets (a ``while_loop`` whose lanes stop
    at their goal; a lane that did not reset walks no step, so under ``vmap`` a step costs
    the longest path among the lanes that reset there, and nothing where none did). The
    view of a pose is a table gather, so the walk moves poses only (the observation of each
    step of the walk is dead code). For the ``oracle`` imagination (foresit_jax.methods),
    a diagnostic of how much a perfect imagination of success could give: no agent sees
    this in a real home."""

    GOAL_KEYS = {"view": "goal_view", "detections": "goal_detections"}

    def goal_observation(self, state, params=None, walk=None):
        """The goal parts ``{"goal_view": ..., ...}`` of the episode starting at ``state``;
        ``walk`` (bool ``[]``, default True): whether to walk at all (False: the parts of
        ``state``'s own view, cheap)."""
        params = self._params(params)
        env = self._env
        walk = jnp.asarray(True) if walk is None else walk
        # A shortest path is at most L^g - 1 moves; the bound only guards a broken table.
        limit = env.shortest_path_length(state, params)

        def cond(carry):
            s, moved = carry
            return walk & ~env.target_in_view(s, params) & (moved < limit)

        def body(carry):
            s, moved = carry
            _, s, *_ = env.step_env(jax.random.PRNGKey(0), s, env.optimal_action(s, params), params)  # deterministic
            return s, moved + 1

        end, _ = jax.lax.while_loop(cond, body, (state, jnp.zeros((), jnp.int32)))
        obs = env.get_obs(end, params)
        return {goal: obs[key] for key, goal in self.GOAL_KEYS.items() if key in obs}

    def observation_space(self, params=None):
        inner = self._env.observation_space(params)
        parts = dict(inner.spaces)
        for key, goal in self.GOAL_KEYS.items():
            if key in parts:
                parts[goal] = parts[key]
        return spaces.Dict(parts)

    def reset(self, key, params=None):
        params = self._params(params)
        obs, env_state = self._env.reset(key, params)
        goal = self.goal_observation(env_state, params)
        return {**obs, **goal}, GoalViewState(env_state, goal)

    def step(self, key, state, action, params=None):
        params = self._params(params)
        obs, env_state, reward, terminated, truncated, info = self._env.step(key, state.env_state, action, params)
        done = terminated | truncated  # the returned state is the next episode's start there
        fresh = self.goal_observation(env_state, params, walk=done)
        goal = jax.tree.map(lambda f, g: jnp.where(done, f, g), fresh, state.goal)
        return {**obs, **goal}, GoalViewState(env_state, goal), reward, terminated, truncated, info

    @staticmethod
    def goal_of(obs: dict) -> dict:
        """The goal view as an observation of the wrapped env (its view and detections
        replaced by the goal's; the target kept), for an encoder that reads those keys."""
        goal = {key: obs[goal] for key, goal in GoalViewWrapper.GOAL_KEYS.items() if goal in obs}
        return {key: value for key, value in obs.items() if key not in GoalViewWrapper.GOAL_KEYS.values()} | goal


# The privileged cues of `CueWrapper`: name -> its width in floats.
CUES: dict[str, int] = {"optimal_action": 6, "compass": 3, "compass_at_start": 3}


@struct.dataclass
class CueState:
    """The wrapped env's state and the cue the running episode holds (``compass_at_start``;
    the per-step cues keep their last value here too, unused)."""

    env_state: object
    cue: jax.Array  # float32 [K]


class CueWrapper(Wrapper):
    """Privileged, for diagnostics: every observation also carries ``obs["cue"]``, float32
    ``[K]``, a fact no agent sees in a real home, to test what a channel of the agent can
    carry (docs/plans/ceiling_channels.md). ``cue``:

    - ``"optimal_action"``: a one-hot ``[6]`` of the oracle's action from the current pose
      (``optimal_action``: Done where Done succeeds), renewed every step: a policy that
      copies it is optimal, so it checks the plumbing of a channel;
    - ``"compass"``: the target's egocentric bearing and distance ``[3]``, renewed every
      step: ``(cos b, sin b, d / G)`` with b the angle from the agent's heading to the
      nearest cell holding the target's category (clockwise positive, radians), d that
      cell's Euclidean distance in cells, G the grid's side;
    - ``"compass_at_start"``: the compass of the episode's start pose, held for the
      episode (renewed only where an episode begins): the timing of the goal view, which
      is fixed for the episode too.

    Reads the wrapped env's state (pose, scene, target) and its scene bank, as
    ``GoalViewWrapper`` does; the cue after a step is that of the state ``step`` returns,
    so after an automatic reset it is the next episode's."""

    def __init__(self, env, cue: str):
        if cue not in CUES:
            raise ValueError(f"cue must be one of {tuple(CUES)}, got {cue!r}")
        super().__init__(env)
        self.cue = cue

    def compass(self, state, params=None) -> jax.Array:
        """float32 [3]: (cos b, sin b, d / G) of the nearest target cell from ``state``'s pose."""
        params = self._params(params)
        grid = self._env.grid_size
        cells = params.bank.obj_cat[state.scene] == state.target  # [G, G]
        rows, cols = jnp.meshgrid(jnp.arange(grid), jnp.arange(grid), indexing="ij")
        d_row, d_col = rows - state.agent_pos[0], cols - state.agent_pos[1]
        dist2 = jnp.where(cells, d_row**2 + d_col**2, jnp.iinfo(jnp.int32).max)
        nearest = jnp.argmin(dist2)
        d_row, d_col = d_row.reshape(-1)[nearest], d_col.reshape(-1)[nearest]
        # Heading 0 is north (row - 1), clockwise in 45 degree steps: the absolute bearing
        # of (d_row, d_col) clockwise from north is atan2(d_col, -d_row).
        bearing = jnp.arctan2(d_col, -d_row) - state.heading * (jnp.pi / 4)
        distance = jnp.sqrt((d_row**2 + d_col**2).astype(jnp.float32)) / grid
        return jnp.stack([jnp.cos(bearing), jnp.sin(bearing), distance]).astype(jnp.float32)

    def cue_of(self, state, params=None) -> jax.Array:
        """The cue ``[K]`` at the inner env's ``state`` (for ``compass_at_start``, at a start)."""
        params = self._params(params)
        if self.cue == "optimal_action":
            return jax.nn.one_hot(self._env.optimal_action(state, params), CUES[self.cue], dtype=jnp.float32)
        return self.compass(state, params)

    def observation_space(self, params=None):
        parts = dict(self._env.observation_space(params).spaces)
        width = CUES[self.cue]
        low = np.zeros(width, np.float32) if self.cue == "optimal_action" else np.array([-1, -1, 0], np.float32)
        high = np.ones(width, np.float32) if self.cue == "optimal_action" else np.array([1, 1, np.sqrt(2)], np.float32)
        parts["cue"] = spaces.Box(low, high, (width,), jnp.float32)
        return spaces.Dict(parts)

    def reset(self, key, params=None):
        params = self._params(params)
        obs, env_state = self._env.reset(key, params)
        cue = self.cue_of(env_state, params)
        return {**obs, "cue": cue}, CueState(env_state, cue)

    def step(self, key, state, action, params=None):
        params = self._params(params)
        obs, env_state, reward, terminated, truncated, info = self._env.step(key, state.env_state, action, params)
        cue = self.cue_of(env_state, params)
        if self.cue == "compass_at_start":  # renewed where the returned state starts an episode
            cue = jnp.where(terminated | truncated, cue, state.cue)
        return {**obs, "cue": cue}, CueState(env_state, cue), reward, terminated, truncated, info
