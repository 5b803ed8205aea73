"""GridNav for code written against gymnax: ``envs.make_gymnax``.

    env, params = envs.make_gymnax("GridNav-v0")   # where the code had gymnax.make("CartPole-v1")
    obs, state = env.reset(key, params)            # obs: float32 [N], one flat vector
    obs, state, reward, done, info = env.step(key, state, action, params)

What it returns is what ``gymnax.make`` returns for one of gymnax's own environments:

- the observation is one flat float32 vector (the layout of
  ``envs.wrappers.FlattenObservationWrapper``: view, target, then ORG's detections), and
  ``observation_space`` a ``Box`` of that size; ``action_space`` is ``Discrete(6)``.  The
  space classes are gymnax's own (``gymnax.environments.spaces``) when gymnax is installed,
  so its wrappers' ``isinstance`` checks pass, and ``envs.spaces``' look-alikes otherwise.
- ``step`` resets automatically and returns the values of one fixed step convention,
  ``step_api``, whatever is installed (it never changes under a user who installs gymnax 1.x,
  e.g. with the ``rejax`` extra):

  - ``"done"`` (the default), five values ``obs, state, reward, done, info`` with
    ``done = terminated | truncated``: gymnax before 1.0, and what PureJaxRL's ``ppo.py``
    and wrappers and rejax 0.1.3 unpack.  ``info`` has no ``final_observation`` unless
    ``final_observation=True``.
  - ``"terminated_truncated"``, six values ``obs, state, reward, terminated, truncated,
    info``: gymnax 1.0 and later (``step_api="terminated_truncated"`` for code written
    against gymnax 1.x, e.g. gymnax 1.x's own ``gymnax.wrappers.purerl``).
    ``info["final_observation"]`` (the flat observation before the reset) is there by
    default, since gymnax 1.x's own ``FlattenObservationWrapper`` reads it at every step.
  - ``"auto"``: the installed gymnax's convention (six values from gymnax 1.0 on, five
    before it or without it: ``installed_step_api()``).

  The default is ``"done"`` whatever is installed, and nothing is warned of. gymnax 1.x's
  own wrappers (``gymnax.wrappers.purerl.LogWrapper``, ``FlattenObservationWrapper``)
  unpack six values: wrap ``make_gymnax("GridNav-v0", step_api="terminated_truncated")``
  with them (the default five-value env fails their unpacking), as docs/usage.md shows.

  Either way ``info`` holds GridNav's facts about the step (``success``,
  ``episode_length``, ``optimal_length``, ``room_type``, ``scene``, ``target``,
  ``terminated``, ``truncated``: ``envs.gridnav.GridNav``).
- ``default_params`` is computed once (the params of the split asked for), as a
  ``GymnaxEnvParams``: GridNav's params with gymnax's ``max_steps_in_episode`` (the longest
  time limit of those params: 30 steps for training), hashed and compared by identity, as
  a static ``jit`` argument needs (GridNav's params hold the scene bank as device arrays,
  which cannot be hashed), and copied as themselves (they are immutable: ``copy.deepcopy``
  of a client's config shares the bank instead of copying it, and stays the same key).
- gymnax 1.x ``Environment``'s other members, which do not depend on what is installed:
  ``name``, ``num_actions``, ``reset_env``, ``get_obs`` (``get_obs(state, params=None,
  key=None)``, gymnax 1.x's signature: GridNav's observation does not depend on the key);
  ``step_env`` (no automatic reset; five values as gymnax 1.x's: ``obs, state, reward,
  terminated, info`` under ``"terminated_truncated"``, ``obs, state, reward, done, info``
  under ``"done"``);
  ``is_terminated`` (always False: GridNav's episodes end by the Done action, which the
  state does not record), ``is_truncated`` (GridNav's own time limit,
  ``state.time >= params.max_steps[state.room_type]``), ``discount`` (0 where terminated,
  else 1, as gymnax's) and ``state_space`` (a ``Dict`` of ``EnvState``'s fields).

``register_gymnax()`` adds GridNav-v0 to gymnax's registry (gymnax 1.0 and later have
one; it returns False for an older gymnax or none), after which
``gymnax.make("GridNav-v0", **kwargs)`` is ``make_gymnax`` with those keywords, with the
same defaults: ``gymnax.make("GridNav-v0")`` returns the five-value env,
``gymnax.make("GridNav-v0", step_api="terminated_truncated")`` the six-value one.
rejax's string path goes through it too:
``PPO.create(env="GridNav-v0", env_params={"room_types": ["bathroom"]}, ...)`` (after
``envs.register_gymnax()``) calls ``gymnax.make("GridNav-v0", room_types=["bathroom"])``
(rejax 0.1.3 passes ``env_params`` as ``gymnax.make``'s keywords), so it trains on the
five-value env rejax unpacks (leave ``step_api`` at its default there).
``import envs`` registers it when gymnax has been imported already; importing gymnax takes
seconds, so ``envs`` never imports it itself.  gymnax is an optional dependency: nothing
here needs it.
"""

from __future__ import annotations

import functools
import importlib.util

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from envs import catalog as C
from envs import spaces
from envs.bank import UNREACHABLE
from envs.gridnav import EnvParams, GridNav
from envs.versions import installed_version
from envs.wrappers import FlattenObservationWrapper

STEP_APIS = ("auto", "done", "terminated_truncated")
DEFAULT_STEP_API = "done"  # fixed, whatever is installed


def installed_gymnax_version() -> tuple[int, ...] | None:
    """(major, minor, patch) of the installed gymnax, or None when it is not installed."""
    if importlib.util.find_spec("gymnax") is None:
        return None
    return installed_version("gymnax")  # None when importable but without metadata


def default_step_api() -> str:
    """The step convention ``make_gymnax`` uses when ``step_api`` is not passed: ``"done"``
    (five values), whatever is installed (``installed_step_api`` gives the installed
    gymnax's)."""
    return DEFAULT_STEP_API


def installed_step_api() -> str:
    """The step convention of the installed gymnax (what ``step_api="auto"`` chooses): six
    values from 1.0 on, five before (and without gymnax, PureJaxRL's five)."""
    version = installed_gymnax_version()
    return "terminated_truncated" if version is not None and version >= (1,) else "done"


def _resolve_step_api(step_api: str | None) -> str:
    """ "done" or "terminated_truncated" for a ``step_api`` argument (None: not passed)."""
    if step_api is not None and step_api not in STEP_APIS:
        raise ValueError(f"step_api must be one of {STEP_APIS}, got {step_api!r}")
    if step_api is None:
        return DEFAULT_STEP_API
    return installed_step_api() if step_api == "auto" else step_api


def _import_gymnax(module: str = "gymnax"):
    """Import a gymnax module, or say in one line why an installed gymnax cannot be."""
    try:
        return importlib.import_module(module)
    except ImportError as error:
        raise ImportError(
            f"gymnax {'.'.join(map(str, installed_gymnax_version() or ()))} is installed but cannot be "
            f"imported ({type(error).__name__}: {error}); gymnax 1.0.1 imports `six` without declaring it: "
            f"pip install six (or pip install 'foresit_jax[gymnax]')"
        ) from error


def _space_classes():
    """gymnax's space module when gymnax is installed, else ``envs.spaces``."""
    if installed_gymnax_version() is None:
        return spaces
    return _import_gymnax("gymnax.environments.spaces")  # optional dependency


@struct.dataclass
class GymnaxEnvParams(EnvParams):
    """GridNav's params as gymnax clients hold them (``make_gymnax`` returns them).

    - ``max_steps_in_episode``: gymnax's name for the episode limit (rejax's evaluator and
      others read it as a loop bound); here the longest of ``max_steps`` (each room type's
      limit still truncates its own episodes). Static (part of the pytree's structure), so it
      stays a Python int under ``jit``, as gymnax's is.
    - Hashed and compared by identity: gymnax's params are scalars and hash by value, and
      some clients pass them to ``jit`` as a static argument; these hold the scene bank, whose
      arrays cannot be hashed. Identity is what a static argument needs: the same params
      object finds the compiled program again, another one compiles its own.
    - ``copy.copy`` and ``copy.deepcopy`` return the params themselves: they are immutable
      (a frozen dataclass of immutable jax arrays), as copying a tuple returns it.
    """

    max_steps_in_episode: int = struct.field(pytree_node=False, default=30)

    def __hash__(self) -> int:
        return id(self)

    def __eq__(self, other) -> bool:
        return self is other

    def __copy__(self):
        return self

    def __deepcopy__(self, memo):
        return self

    @classmethod
    def of(cls, params: EnvParams) -> "GymnaxEnvParams":
        """GridNav's params with gymnax's fields added."""
        if isinstance(params, cls):
            return params
        fields = {f: getattr(params, f) for f in params.__dataclass_fields__}
        return cls(**fields, max_steps_in_episode=int(np.max(np.asarray(params.max_steps))))


class GymnaxGridNav:
    """GridNav behind the interface of a gymnax ``Environment`` (see the module docstring).

    Build it with ``make_gymnax``.  ``reset`` and ``step`` are jitted with the environment
    static, as gymnax's are; under an outer jit or vmap they trace inline.
    """

    def __init__(self, env: GridNav, params, step_api: str):
        if step_api not in ("done", "terminated_truncated"):
            raise ValueError(f"GymnaxGridNav takes step_api 'done' or 'terminated_truncated', got {step_api!r}")
        self._flat = FlattenObservationWrapper(env)
        self.gridnav = env
        self.step_api = step_api
        self._params = GymnaxEnvParams.of(params)

    # ----------------------------------------------------------------- gymnax API
    @property
    def name(self) -> str:
        return self.gridnav.name

    @property
    def num_actions(self) -> int:
        return self.gridnav.num_actions

    @property
    def default_params(self):
        """The params of the split ``make_gymnax`` was asked for, built once."""
        return self._params

    @property
    def final_observation(self) -> bool:
        return self.gridnav.final_observation

    def observation_space(self, params=None):
        box = self._flat.observation_space(params)
        return _space_classes().Box(box.low, box.high, box.shape, box.dtype)

    def action_space(self, params=None):
        return _space_classes().Discrete(self.num_actions)

    @functools.partial(jax.jit, static_argnames=("self",))
    def reset(self, key: jax.Array, params=None):
        return self.reset_env(key, self.default_params if params is None else params)

    @functools.partial(jax.jit, static_argnames=("self",))
    def step(self, key: jax.Array, state, action, params=None):
        params = self.default_params if params is None else params
        return self._in_convention(*self._flat.step(key, state, action, params))

    def reset_env(self, key: jax.Array, params):
        return self._flat.reset(key, params)

    def step_env(self, key: jax.Array, state, action, params):
        """One step without automatic reset, five values as gymnax 1.x's ``step_env``:
        ``obs, state, reward, terminated, info`` under step_api "terminated_truncated"
        (gymnax 1.x's ``step`` adds ``truncated`` from ``is_truncated``), ``obs, state,
        reward, done, info`` with ``done = terminated | truncated`` under "done" (gymnax
        0.x's).  ``info`` is GridNav's (with ``terminated`` and ``truncated``)."""
        obs, state, reward, terminated, truncated, info = self.gridnav.step_env(key, state, action, params)
        flag = terminated | truncated if self.step_api == "done" else terminated
        return self._flat.flatten(obs, params), state, reward, flag, info

    def get_obs(self, state, params=None, key=None):
        """The flat observation of ``state``: gymnax 1.x's ``get_obs(state, params=None,
        key=None)`` (GridNav's observation does not depend on ``key``)."""
        del key
        params = self.default_params if params is None else params
        return self._flat.flatten(self.gridnav.get_obs(state, params), params)

    def observe(self, key, state, action=None, params=None):
        """The flat observation of ``state`` (gymnax's keyed hook: GridNav's observation
        depends on neither ``key`` nor ``action``)."""
        del key, action
        return self.get_obs(state, params)

    def is_terminal(self, state, params=None) -> jax.Array:
        """gymnax's legacy name for ``is_terminated`` (time limits excluded, as there)."""
        return self.is_terminated(state, params)

    def is_terminated(self, state, params=None) -> jax.Array:
        """Always False: GridNav's episodes end by the Done action, which the state does not
        record (``step`` and ``step_env`` return ``terminated``; the state after a Done is not
        itself terminal)."""
        return jnp.zeros_like(state.time, dtype=bool)

    def is_truncated(self, state, params=None) -> jax.Array:
        """Whether the state has reached GridNav's own time limit, that of its room type:
        ``state.time >= params.max_steps[state.room_type]`` (not gymnax's
        ``max_steps_in_episode``, the longest of them)."""
        params = self.default_params if params is None else params
        return state.time >= params.max_steps[state.room_type]

    def discount(self, state, params=None) -> jax.Array:
        """0 where ``is_terminated``, else 1 (so always 1), as gymnax's."""
        terminated = self.is_terminated(state, params)
        return jax.lax.select(
            terminated, jnp.zeros(terminated.shape, jnp.float32), jnp.ones(terminated.shape, jnp.float32)
        )

    def state_space(self, params=None):
        """A ``Dict`` space of ``EnvState``'s fields, in its order (the space classes of
        ``observation_space``), bounds from ``params``: ``agent_pos`` in [0, grid_size),
        ``heading`` 8, ``horizon`` 2, ``scene`` the bank's scene count, ``room_type`` 4,
        ``target`` the setup's category count, ``target_slot`` the bank's targets per scene,
        ``time`` in [0, the longest time limit], ``optimal_length`` in [1, the bank's longest
        finite distance]."""
        params = self.default_params if params is None else params
        sp, bank, grid = _space_classes(), params.bank, self.gridnav.grid_size
        distance = bank.distance.astype(jnp.int32)
        longest = jnp.max(jnp.where(distance < UNREACHABLE, distance, 0))
        parts = {
            "agent_pos": sp.Box(0, grid - 1, (2,), jnp.int32),
            "heading": sp.Discrete(C.NUM_HEADINGS),
            "horizon": sp.Discrete(C.NUM_HORIZONS),
            "scene": sp.Discrete(int(bank.numbers.shape[0])),
            "room_type": sp.Discrete(len(C.ROOM_TYPES)),
            "target": sp.Discrete(self.gridnav.num_categories),
            "target_slot": sp.Discrete(int(bank.targets.shape[1])),
            "time": sp.Box(0, jnp.max(params.max_steps), (), jnp.int32),
            "optimal_length": sp.Box(1, longest, (), jnp.int32),
        }
        return sp.Dict(parts)

    def _in_convention(self, obs, state, reward, terminated, truncated, info):
        if self.step_api == "done":
            return obs, state, reward, terminated | truncated, info
        return obs, state, reward, terminated, truncated, info

    def __repr__(self) -> str:
        return f"GymnaxGridNav({self.gridnav.setup!r}, step_api={self.step_api!r})"


def make_gymnax(
    env_id: str = "GridNav-v0",
    *,
    step_api: str | None = None,
    final_observation: bool | None = None,
    setup: str = "savn",
    split: str = "train",
    room_types=None,
    training: bool | None = None,
    **env_kwargs,
):
    """``(env, params)`` as ``gymnax.make`` returns them (see the module docstring).

    Args:
      env_id: "GridNav-v0".
      step_api: the step convention, fixed whatever is installed:
        "done" (the default: five values ``obs, state, reward, done, info``, what
        PureJaxRL's ``ppo.py`` and rejax 0.1.3 unpack), "terminated_truncated" (six,
        gymnax 1.x's ``obs, state, reward, terminated, truncated, info``) or "auto" (the
        installed gymnax's: ``installed_step_api()``).
      final_observation: put the flat observation before the automatic reset in
        ``info["final_observation"]``; by default only with the six-value step.
      setup, split, room_types, training, env_kwargs: as ``envs.make``.

    ``gymnax.make("GridNav-v0", **kwargs)`` (after ``envs.register_gymnax()``) is this
    function with those keywords and the same defaults: five values unless ``step_api`` is
    passed.  So is rejax's string path, ``PPO.create(env="GridNav-v0",
    env_params={"room_types": ["bathroom"]}, ...)``: rejax 0.1.3 passes ``env_params`` to
    ``gymnax.make`` as keywords, and trains on the five-value env.
    """
    from envs import make  # envs/__init__ imports this module

    step_api = _resolve_step_api(step_api)
    if final_observation is None:
        final_observation = step_api == "terminated_truncated"
    env, params = make(
        env_id,
        setup=setup,
        split=split,
        room_types=room_types,
        training=training,
        final_observation=bool(final_observation),
        **env_kwargs,
    )
    wrapped = GymnaxGridNav(env, params, step_api)
    return wrapped, wrapped.default_params


def _gymnax_factory(env_id: str, **kwargs) -> GymnaxGridNav:
    """``gymnax.make(env_id, **kwargs)``'s env: ``make_gymnax``'s, with its defaults."""
    kwargs["step_api"] = _resolve_step_api(kwargs.get("step_api"))
    return make_gymnax(env_id, **kwargs)[0]


def register_gymnax() -> bool:
    """Add GridNav's ids to gymnax's registry, so that ``gymnax.make("GridNav-v0", **kw)``
    works.  Returns whether gymnax has a registry to add to (gymnax 1.0 and later).
    Calling it again is harmless."""
    from envs import REGISTERED

    if installed_gymnax_version() is None:
        return False
    registration = _import_gymnax("gymnax.registration")  # optional dependency
    register = getattr(registration, "register", None)
    if register is None:  # gymnax before 1.0: make() is a fixed list
        return False
    for env_id in REGISTERED:
        if env_id not in getattr(registration, "registered_envs", ()):
            register(env_id, functools.partial(_gymnax_factory, env_id))
    return True


__all__ = [
    "DEFAULT_STEP_API",
    "STEP_APIS",
    "GymnaxEnvParams",
    "GymnaxGridNav",
    "default_step_api",
    "installed_gymnax_version",
    "installed_step_api",
    "make_gymnax",
    "register_gymnax",
]
