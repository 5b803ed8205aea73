"""gymnax-style spaces (Discrete, Box, Dict) so that ``envs`` needs no gymnax.

The classes have gymnax's attribute names and methods (``gymnax.environments.spaces``):
``Discrete.n``, ``shape``, ``dtype``; ``Box.low``, ``high``, ``shape``, ``dtype``;
``Dict.spaces``, ``num_spaces``; ``sample(key)`` and ``contains(x)`` on all.  Code that
only reads those (PureJaxRL's ``env.action_space(params).n``,
``env.observation_space(params).shape``) works with them unchanged.

Code that checks ``isinstance(space, gymnax.environments.spaces.Box)`` (gymnax's own
wrappers) needs gymnax's classes: convert with ``to_gymnax``, e.g. a wrapper whose
``observation_space`` returns ``to_gymnax(env.observation_space(params))``, or, for the
usual case of gymnax's ``FlattenObservationWrapper``, use
``envs.wrappers.FlattenObservationWrapper`` instead (it also flattens the dict
observation of GridNav, which gymnax's wrapper cannot).  gymnax is imported only inside
``to_gymnax``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np


class Space:
    """Base class: ``sample(key)`` and ``contains(x)``, both jittable."""

    def sample(self, key: jax.Array):
        raise NotImplementedError

    def contains(self, x) -> jax.Array:
        raise NotImplementedError


class Discrete(Space):
    """Integers 0 .. n-1."""

    def __init__(self, num_categories: int, dtype=jnp.int32):
        if int(num_categories) < 0:
            raise ValueError(f"num_categories must be non-negative, got {num_categories}")
        self.n = int(num_categories)
        self.shape: tuple[int, ...] = ()
        self.dtype = dtype

    def sample(self, key: jax.Array) -> jax.Array:
        return jax.random.randint(key, self.shape, 0, self.n).astype(self.dtype)

    def contains(self, x) -> jax.Array:
        x = jnp.asarray(x)
        return (x >= 0) & (x < self.n)

    def __repr__(self) -> str:
        return f"Discrete({self.n})"


class Box(Space):
    """Arrays of a fixed shape and dtype with values in [low, high] (scalars or arrays of
    that shape)."""

    def __init__(self, low, high, shape: tuple[int, ...], dtype=jnp.float32):
        self.low, self.high, self.shape, self.dtype = low, high, tuple(int(d) for d in shape), dtype

    def sample(self, key: jax.Array) -> jax.Array:
        """Uniform in [low, high]; infinite bounds are clipped to +-1e3."""
        low = jnp.maximum(jnp.asarray(self.low, jnp.float32), -1e3)
        high = jnp.minimum(jnp.asarray(self.high, jnp.float32), 1e3)
        return jax.random.uniform(key, self.shape, jnp.float32, low, high).astype(self.dtype)

    def contains(self, x) -> jax.Array:
        x = jnp.asarray(x)
        return (x.shape == self.shape) & jnp.all(x >= self.low) & jnp.all(x <= self.high)

    def __repr__(self) -> str:
        return f"Box(shape={self.shape}, dtype={jnp.dtype(self.dtype).name})"


class Dict(Space):
    """A dictionary of spaces; samples and observations are dicts with the same keys."""

    def __init__(self, spaces: dict[str, Any]):
        self.spaces = dict(spaces)
        self.num_spaces = len(self.spaces)

    def sample(self, key: jax.Array) -> dict[str, jax.Array]:
        keys = jax.random.split(key, len(self.spaces))
        return {name: space.sample(k) for (name, space), k in zip(self.spaces.items(), keys)}

    def contains(self, x) -> jax.Array:
        """``x`` a mapping with the same keys (or, as in gymnax, an object with those attributes)."""
        if isinstance(x, Mapping):
            if set(x) != set(self.spaces):
                return jnp.asarray(False)
            get = x.__getitem__
        else:
            get = lambda k: getattr(x, k)  # noqa: E731
        return jnp.all(jnp.stack([jnp.asarray(s.contains(get(k))) for k, s in self.spaces.items()]))

    def __getitem__(self, name: str):
        return self.spaces[name]

    def __repr__(self) -> str:
        return f"Dict({self.spaces})"


def to_gymnax(space: Space, gymnax_spaces=None):
    """The equivalent gymnax space (``gymnax.environments.spaces`` Discrete, Box or Dict).

    For gymnax code that checks ``isinstance`` against its own classes.  gymnax is imported
    here only (it is not a dependency of ``envs``); ``gymnax_spaces`` can stand in for the
    module (anything with Discrete, Box and Dict classes of gymnax's constructors).
    """
    if gymnax_spaces is None:
        from gymnax.environments import spaces as gymnax_spaces  # optional dependency
    if isinstance(space, Discrete):
        return gymnax_spaces.Discrete(space.n)
    if isinstance(space, Box):
        return gymnax_spaces.Box(space.low, space.high, space.shape, space.dtype)
    if isinstance(space, Dict):
        return gymnax_spaces.Dict({k: to_gymnax(s, gymnax_spaces) for k, s in space.spaces.items()})
    raise TypeError(f"cannot convert {type(space).__name__} to a gymnax space")


def flat_size(space: Space) -> int:
    """Number of scalars in one element of a Box or Discrete space, or of a Dict of them."""
    if isinstance(space, Dict):
        return sum(flat_size(s) for s in space.spaces.values())
    return int(np.prod(space.shape, dtype=np.int64))


__all__ = ["Box", "Dict", "Discrete", "Space", "flat_size", "to_gymnax"]
