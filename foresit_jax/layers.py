"""Dense layers written for XLA:CPU's speed, with `nn.Dense`'s parameters (an optimisation
of their own, tested equal to `nn.Dense` in tests/agent/test_layers.py).

* `Dense`: `nn.Dense` (same parameters, names, initialisation) computed on a 2-D view of
  its input. Flax's Dense contracts the last axis of an input of any rank; for the
  batched inputs of a training window (`[T * B, 3, W, C]` grids, `[B, K, H]` keys,
  `[T * B, N, 6]` detections) XLA:CPU then runs the backward pass (the kernel's and the
  bias's gradients, contractions over several leading axes) much slower than the same
  layer on `[T * B * 3 * W, C]` (docs/design.md, 'Speed'). Flattening the leading axes
  changes nothing else.
* `GridDense`: `Dense([grid : tile(v_1) : ... : tile(v_n)])` over a `[..., R, W, C]` grid
  and per-sample vectors `v_i [..., D_i]` tiled over it, without building the tiled
  input: the kernel's rows split into the grid's and each vector's, so the vectors'
  share is computed once per sample instead of once per grid cell, and its gradient
  needs no reduction over the grid (SAVN's encoder tiles the target and the previous
  action over its 7 x 7 grid before a 1 x 1 convolution: the same function).
"""

from __future__ import annotations

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp


class Dense(nn.Dense):
    """`nn.Dense` on a 2-D view of its input (see the module docstring); any leading dims."""

    def __call__(self, inputs: chex.Array) -> chex.Array:
        lead = inputs.shape[:-1]
        out = super().__call__(jnp.reshape(inputs, (-1, inputs.shape[-1])))
        return jnp.reshape(out, (*lead, out.shape[-1]))


class GridDense(nn.Module):
    """`nn.Dense(features)` of `[grid : tile(v_1) : ... ]` along the channel axis
    (see the module docstring). Its parameters are the Dense's: `kernel [C + sum D_i, F]`
    (lecun normal), `bias [F]` (zeros).

    `__call__(grid [..., R, W, C], *vectors [..., D_i]) -> [..., R, W, F]`."""

    features: int

    @nn.compact
    def __call__(self, grid: chex.Array, *vectors: chex.Array) -> chex.Array:
        batch_shape = grid.shape[:-3]
        chex.assert_equal_shape_prefix([grid, *vectors], len(batch_shape))
        sizes = [grid.shape[-1]] + [v.shape[-1] for v in vectors]
        kernel = self.param("kernel", nn.initializers.lecun_normal(), (sum(sizes), self.features))
        bias = self.param("bias", nn.initializers.zeros_init(), (self.features,))
        cells = jnp.dot(jnp.reshape(grid, (-1, sizes[0])), kernel[: sizes[0]])  # [cells, F]
        cells = jnp.reshape(cells, grid.shape[:-1] + (self.features,))
        if not vectors:
            return cells + bias
        per_sample = jnp.concatenate([jnp.reshape(v, (-1, v.shape[-1])) for v in vectors], axis=-1)
        per_sample = jnp.reshape(jnp.dot(per_sample, kernel[sizes[0] :]) + bias, (*batch_shape, self.features))
        return cells + per_sample[..., None, None, :]


def orthogonal(scale: float = 1.0):
    """`nn.initializers.orthogonal(scale)` drawn one sample at a time under `vmap`.

    Vmapped (several seeds initialised in one program), flax's initialiser is one batched
    QR (LAPACK geqrf/orgqr) per parameter. jaxlib 0.10's CPU LAPACK kernels split a batch
    over XLA:CPU's intra-op thread pool and block a pool thread until its chunks are done;
    two such QRs running side by side (the LSTM's recurrent kernels and the actor) can
    occupy every thread of a 2-thread pool and wait on each other forever. Here a batch of
    keys is drawn by `lax.map`, one unbatched QR after another, nothing batched to split.
    Under `jit` the values are flax's batched draw's, bit for bit. Eagerly vmapped they are
    flax's compiled draw's, which for some shapes (the actor's) differs from flax's eager
    draw in the last bit (docs/design.md, "A known hazard")."""
    base = nn.initializers.orthogonal(scale)

    def init(key, shape, dtype=jnp.float32):
        @jax.custom_batching.custom_vmap
        def draw(key):
            return base(key, shape, dtype)

        @draw.def_vmap
        def _(axis_size, in_batched, key):
            del axis_size
            (batched,) = in_batched
            return (jax.lax.map(draw, key), True) if batched else (draw(key), False)

        return draw(key)

    return init
