"""Categorical distribution over discrete actions, parameterised by logits.

Written by hand (a few lines each) instead of pulling in distrax/rlax. Every function
works on a trailing action axis and broadcasts over any leading batch axes:
`logits` is `[..., A]`, actions are integer `[...]`.
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp


def log_softmax(logits: chex.Array) -> chex.Array:
    """Numerically stable log-probabilities, `[..., A] -> [..., A]`."""
    shifted = logits - jax.lax.stop_gradient(jnp.max(logits, axis=-1, keepdims=True))
    return shifted - jnp.log(jnp.sum(jnp.exp(shifted), axis=-1, keepdims=True))


def probs(logits: chex.Array) -> chex.Array:
    """Action probabilities (softmax), `[..., A] -> [..., A]`."""
    return jnp.exp(log_softmax(logits))


def log_prob(logits: chex.Array, action: chex.Array) -> chex.Array:
    """log pi(action), `logits [..., A]`, `action [...]` int -> `[...]`."""
    chex.assert_equal_shape_prefix([logits, action], action.ndim)
    logp = log_softmax(logits)  # [..., A]
    return jnp.take_along_axis(logp, action[..., None].astype(jnp.int32), axis=-1)[..., 0]


def entropy(logits: chex.Array) -> chex.Array:
    """H(pi) = -sum_a pi(a) log pi(a), in nats, `[..., A] -> [...]`."""
    logp = log_softmax(logits)  # [..., A]
    return -jnp.sum(jnp.exp(logp) * logp, axis=-1)


def sample(key: chex.PRNGKey, logits: chex.Array) -> chex.Array:
    """Draw actions by the Gumbel-max trick, `[..., A] -> [...]` int32."""
    gumbel = jax.random.gumbel(key, logits.shape, dtype=jnp.float32)  # [..., A]
    return jnp.argmax(logits + gumbel, axis=-1).astype(jnp.int32)


def greedy(logits: chex.Array) -> chex.Array:
    """The most likely action (ties to the lowest index), `[..., A] -> [...]` int32."""
    return jnp.argmax(logits, axis=-1).astype(jnp.int32)
