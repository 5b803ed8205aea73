"""SAVN's learned interaction loss L_phi (`LearnedLoss`), the maml base's only module of
its own: a flax module that `foresit_jax.networks.ActorCritic` holds (as `learned_loss`,
params["params"]["learned_loss"]) when the base adapts in its episodes. The inner loop
that reads it is `foresit_jax.maml`'s.

Read from allenai/savn (models/tcn.py, models/savn.py): L_phi reads the last `segment` (6)
[h_t : pi_t] rows of an episode as a `[6, H + A]` block whose 6 steps are the CHANNELS of a
1-d convolution sliding over the H + A features (SAVN's `ll_tc`: Conv1d 6->10, kernel 2,
dilation 1, then 10->1, kernel 2, dilation 2, each causal (left zero padding, PyTorch's
pad-and-chomp) and followed by a leaky ReLU of slope 0.01; no weight norm, dropout or
residual: SAVN's `TemporalBlock.net` uses its first conv only). L_phi is the L2 norm of the
`[H + A]` output, sqrt(sum x^2 + 1e-12) (SAVN's plain sqrt has an infinite gradient at 0).
"""

from __future__ import annotations

from typing import Callable

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp

SCOPE = "learned_loss"  # params["params"]["learned_loss"]: phi (ActorCritic's attribute name)


def _torch_default_init(fan_in: int):
    """PyTorch's default Conv1d init, U(+-1/sqrt(fan_in)) for weights and biases: SAVN's
    ll_* layers keep it (its own init runs before they are created)."""
    bound = 1.0 / jnp.sqrt(fan_in)
    return lambda key, shape, dtype=jnp.float32: jax.random.uniform(key, shape, dtype, -bound, bound)


class CausalConv1d(nn.Module):
    """`nn.Conv(features, (kernel_size,), kernel_dilation=dilation, padding=causal)` on
    `[length, in]`, with the same parameters (kernel `[K, in, out]`, bias, created in the
    same order, so the same init), written as K shifted matmuls: `lax.conv` has no
    batching rule for the transposed convolutions of a second-order gradient whose kernel
    is batched twice (per seed of a sweep and per lane of the inner loop), and these
    convolutions are tiny."""

    features: int
    kernel_size: int
    dilation: int
    param_init: Callable

    @nn.compact
    def __call__(self, x: chex.Array) -> chex.Array:
        length, in_features = x.shape
        kernel = self.param("kernel", self.param_init, (self.kernel_size, in_features, self.features))
        bias = self.param("bias", self.param_init, (self.features,))
        pad = (self.kernel_size - 1) * self.dilation
        x = jnp.pad(x, ((pad, 0), (0, 0)))
        taps = [x[k * self.dilation : k * self.dilation + length] @ kernel[k] for k in range(self.kernel_size)]
        return sum(taps) + bias


class LearnedLoss(nn.Module):
    """L_phi: `[segment, F]` (F = H + A) -> scalar, SAVN's `learned_loss` (see module doc).

    The segment's steps are the input channels; the convolutions slide over the F
    features, causally (output j sees features <= j)."""

    segment: int = 6
    channels: tuple[int, ...] = (10, 1)
    kernel_size: int = 2

    @nn.compact
    def __call__(self, inputs: chex.Array) -> chex.Array:
        chex.assert_rank(inputs, 2)
        if inputs.shape[0] != self.segment:
            raise ValueError(f"LearnedLoss expects {self.segment} steps, got inputs of shape {inputs.shape}")
        x = inputs.T  # [F, segment]: length F, channels = steps (flax convolutions are channels-last)
        in_channels = self.segment
        for level, out_channels in enumerate(self.channels):
            dilation = 2**level
            init = _torch_default_init(in_channels * self.kernel_size)
            x = CausalConv1d(out_channels, self.kernel_size, dilation, init, name=f"conv{level}")(x)
            x = nn.leaky_relu(x, 0.01)
            in_channels = out_channels
        return jnp.sqrt(jnp.sum(jnp.square(x)) + 1e-12)
