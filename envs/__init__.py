"""GridNav: a jit-compiled, vmapped stand-in for AI2-THOR object-target navigation.

    import jax, envs
    env, params = envs.make("GridNav-v0", setup="savn", split="train")
    obs, state = env.reset(key, params)
    obs, state, reward, terminated, truncated, info = env.step(key, state, action, params)

``envs`` knows nothing of the agent.  Building a split's scene bank takes seconds the first
time; it is then cached on disk (``envs.bank_cache``: ``$FORESIT_CACHE_DIR``, default
``~/.cache/foresit_jax``; ``FORESIT_NO_CACHE=1`` turns that off).  gymnax-style code:
``envs.make_gymnax`` returns ``(env, params)`` as ``gymnax.make`` does (flat float32
observations, gymnax's spaces, a five-value step whatever is installed, six with
``step_api="terminated_truncated"``: ``envs.gymnax_compat``),
and registers GridNav with gymnax's registry when gymnax has been imported before ``envs``
(else ``envs.register_gymnax()``).  ``envs.spaces`` mirrors gymnax's space classes
(``envs.spaces.to_gymnax`` converts them), ``envs.wrappers`` has
``FlattenObservationWrapper``, ``LogWrapper`` and ``LegacyStepAPIWrapper`` (five-value step).
"""

import sys

from envs.versions import check_jax_flax

check_jax_flax()  # before flax is used: one line naming the upgrade, not an error deep in flax

from envs import catalog, metrics, spaces, wrappers
from envs.bank import SceneBank
from envs.dynamics import pose_from_index, pose_index
from envs.catalog import ACTIONS, ROOM_TYPES, SPLITS
from envs.gridnav import EnvParams, EnvState, GridNav, time_limits

REGISTERED = ("GridNav-v0",)


def make(
    env_id: str = "GridNav-v0",
    setup: str = "savn",
    split: str = "train",
    room_types=None,
    training: bool | None = None,
    **env_kwargs,
):
    """Build the environment and the params of one split.

    Args:
      env_id: "GridNav-v0".
      setup: "savn" or "org" (see docs/design.md).
      split: "train" (layouts 1-20), "val" (21, 23, ..., 29) or "test" (22, 24, ..., 30);
        houses split by their number the same way.
      room_types: None for all four, or some of "kitchen", "living_room", "bedroom",
        "bathroom" (names or indices); in houses, the targets standing in such rooms.
      training: time limits of training (30 steps) or evaluation (100, 200 in living
        rooms); by default training limits on "train" and evaluation limits otherwise.
      env_kwargs: static constructor arguments of GridNav (layout="house" for houses of
        2-4 rooms, envs.houses; grid_size, view_width,
        precomputed_views, final_observation=False to leave ``info["final_observation"]``
        out of every step).
    Returns:
      (env, params).
    """
    if env_id not in REGISTERED:
        raise ValueError(f"unknown environment {env_id!r}; registered: {list(REGISTERED)}")
    env = GridNav(setup=setup, **env_kwargs)
    return env, env.make_params(split, room_types=room_types, training=training)


from envs.gymnax_compat import make_gymnax, register_gymnax  # noqa: E402 (needs make and REGISTERED)

if "gymnax" in sys.modules:  # importing gymnax costs seconds: register only if the user has
    register_gymnax()

__all__ = [
    "ACTIONS",
    "ROOM_TYPES",
    "SPLITS",
    "EnvParams",
    "EnvState",
    "GridNav",
    "SceneBank",
    "catalog",
    "make",
    "make_gymnax",
    "metrics",
    "pose_from_index",
    "pose_index",
    "register_gymnax",
    "spaces",
    "time_limits",
    "wrappers",
]
