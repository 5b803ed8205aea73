"""GridNav's dynamics: pose arithmetic and the transition of a pose under an action.

A pose is (cell, heading, camera horizon); ``pose_index`` flattens it for the scene bank's
tables (``envs.bank``, which precomputes every pose's view and successors with
``transition``), and ``GridNav.step`` moves the agent with the same ``transition``.
Pure jax functions of explicit arrays; nothing here knows of scenes, caches or agents.
"""

from __future__ import annotations

import jax.numpy as jnp

from envs import catalog as C


def pose_index(pos, heading, horizon, grid_size: int):
    """Flat index of a pose: ((row * G + col) * 8 + heading) * 2 + horizon."""
    return ((pos[..., 0] * grid_size + pos[..., 1]) * C.NUM_HEADINGS + heading) * C.NUM_HORIZONS + horizon


def pose_from_index(index, grid_size: int):
    """Inverse of pose_index: (pos [..., 2], heading, horizon)."""
    horizon = index % C.NUM_HORIZONS
    rest = index // C.NUM_HORIZONS
    heading = rest % C.NUM_HEADINGS
    cell = rest // C.NUM_HEADINGS
    return jnp.stack([cell // grid_size, cell % grid_size], -1), heading, horizon


def move_ahead(walkable, pos, heading):
    """MoveAhead from ``pos``: the new position, unchanged when blocked.

    walkable: bool [G, G].  A diagonal step also needs both cells it passes between to be
    free (no cutting corners of walls or furniture).
    """
    delta = jnp.asarray(C.HEADING_DELTAS)[heading]
    target = pos + delta
    side_a = pos + delta * jnp.array([1, 0])
    side_b = pos + delta * jnp.array([0, 1])
    ok = walkable[target[0], target[1]] & walkable[side_a[0], side_a[1]] & walkable[side_b[0], side_b[1]]
    return jnp.where(ok, target, pos)


def transition(walkable, pos, heading, horizon, action):
    """The pose after ``action`` (Done leaves the pose unchanged)."""
    moved = move_ahead(walkable, pos, heading)
    pos = jnp.where(action == C.MOVE_AHEAD, moved, pos)
    heading = jnp.where(
        action == C.ROTATE_LEFT,
        (heading - 1) % C.NUM_HEADINGS,
        jnp.where(action == C.ROTATE_RIGHT, (heading + 1) % C.NUM_HEADINGS, heading),
    )
    horizon = jnp.where(
        action == C.LOOK_UP,
        jnp.maximum(horizon - 1, 0),
        jnp.where(action == C.LOOK_DOWN, jnp.minimum(horizon + 1, C.NUM_HORIZONS - 1), horizon),
    )
    return pos, heading, horizon


__all__ = ["move_ahead", "pose_from_index", "pose_index", "transition"]
