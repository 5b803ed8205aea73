"""Minimal gymnax-style spaces (Discrete, Box, Dict) so that envs needs no gymnax."""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp


class Discrete:
    """Integers 0 .. n-1."""

    def __init__(self, num_categories: int):
        self.n = int(num_categories)
        self.shape: tuple[int, ...] = ()
        self.dtype = jnp.int32

    def sample(self, key: jax.Array) -> jax.Array:
        return jax.random.randint(key, self.shape, 0, self.n).astype(self.dtype)

    def contains(self, x) -> jax.Array:
        x = jnp.asarray(x)
        return (x >= 0) & (x < self.n)

    def __repr__(self) -> str:
        return f"Discrete({self.n})"


class Box:
    """Arrays of a fixed shape and dtype with values in [low, high]."""

    def __init__(self, low, high, shape: tuple[int, ...], dtype=jnp.float32):
        self.low, self.high, self.shape, self.dtype = low, high, tuple(shape), dtype

    def sample(self, key: jax.Array) -> jax.Array:
        low = jnp.maximum(jnp.asarray(self.low, jnp.float32), -1e3)
        high = jnp.minimum(jnp.asarray(self.high, jnp.float32), 1e3)
        return jax.random.uniform(key, self.shape, jnp.float32, low, high).astype(self.dtype)

    def contains(self, x) -> jax.Array:
        x = jnp.asarray(x)
        return (x.shape == self.shape) & jnp.all(x >= self.low) & jnp.all(x <= self.high)

    def __repr__(self) -> str:
        return f"Box(shape={self.shape}, dtype={jnp.dtype(self.dtype).name})"


class Dict:
    """A dictionary of spaces; samples and observations are dicts with the same keys."""

    def __init__(self, spaces: dict[str, Any]):
        self.spaces = dict(spaces)

    def sample(self, key: jax.Array) -> dict[str, jax.Array]:
        keys = jax.random.split(key, len(self.spaces))
        return {name: space.sample(k) for (name, space), k in zip(self.spaces.items(), keys)}

    def contains(self, x) -> jax.Array:
        if set(x) != set(self.spaces):
            return jnp.asarray(False)
        return jnp.all(jnp.stack([jnp.asarray(s.contains(x[k])) for k, s in self.spaces.items()]))

    def __getitem__(self, name: str):
        return self.spaces[name]

    def __repr__(self) -> str:
        return f"Dict({self.spaces})"
