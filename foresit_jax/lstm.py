"""The LSTM cell of the encoder, split in two parts for speed (an optimisation of its own,
tested equal to flax's `nn.OptimizedLSTMCell` in tests/agent/test_lstm.py).

The encoder's LSTM is an `nn.OptimizedLSTMCell` (its parameters are what flax creates:
`ii, if, ig, io` input kernels without bias, `hi, hf, hg, ho` recurrent kernels with bias).
Its input part has no recurrence, so the training replay applies it to every step of a
window in one large matmul (`lstm_input_gates`), and only the recurrent part
(`lstm_step`) runs step by step. Together they compute what `nn.OptimizedLSTMCell`
computes: the same concatenated kernels, the same dots, the same additions in the same
order. The parameter names are flax's: a flax upgrade that renames or reorders them
fails `tests/agent/test_lstm.py`, not a run.

`EncoderLSTM` is the encoder's cell with this split path as its methods, which
`ActorCritic.encode` runs: at one step (acting, on kernels made once per window by
`ActorCritic.lstm_kernels`) its `step`, over a window (the loss) its `unroll`;
`encoder_lstm_params(params)` is the
one place that knows where the LSTM sits in the agent's parameter tree: with
`split_encoder_lstm_kernels`, `join_partial_trees` and `with_encoder_lstm_kernels`, for the
maml base, which splits that tree into the kernels it adapts and the rest.
"""

from __future__ import annotations

from typing import Any, Mapping, NamedTuple, Optional

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
from flax import traverse_util

from foresit_jax.layers import orthogonal

LSTMCarry = tuple[chex.Array, chex.Array]  # (c, h), each [..., hidden_size]

LSTM_GATES: tuple[str, ...] = ("i", "f", "g", "o")


ENCODER_LSTM_PATH: tuple[str, ...] = ("params", "encoder", "lstm")


def encoder_lstm_params(params: Mapping[str, Any]) -> Mapping[str, Any]:
    """The encoder LSTM's subtree of an `ActorCritic` parameter tree."""
    for name in ENCODER_LSTM_PATH:
        params = params[name]
    return params


def is_encoder_lstm_kernel(path: tuple[str, ...]) -> bool:
    """Whether a flattened parameter path names one of the encoder LSTM's eight kernels."""
    return path[: len(ENCODER_LSTM_PATH)] == ENCODER_LSTM_PATH and path[-1] == "kernel"


def split_encoder_lstm_kernels(params: Mapping[str, Any]) -> tuple[dict, dict]:
    """(the encoder LSTM's eight kernels, every other parameter): two partial trees of an
    `ActorCritic` parameter tree (the maml base adapts the first as low-rank updates)."""
    flat = traverse_util.flatten_dict(params)
    kernels = {path: x for path, x in flat.items() if is_encoder_lstm_kernel(path)}
    rest = {path: x for path, x in flat.items() if not is_encoder_lstm_kernel(path)}
    return traverse_util.unflatten_dict(kernels), traverse_util.unflatten_dict(rest)


def join_partial_trees(first: Mapping[str, Any], second: Mapping[str, Any]) -> dict:
    """One tree of two partial trees with no leaf in common (the inverse of
    `split_encoder_lstm_kernels`)."""
    return traverse_util.unflatten_dict({**traverse_util.flatten_dict(first), **traverse_util.flatten_dict(second)})


def lane_copies(tree, num_lanes: int):
    """`tree` broadcast to every lane, leaves `[B, ...]`: maml's theta_0 before any inner
    step, or the rollout's fresh success trackers. It lives here, beside the other tree
    helpers, so that a rollout without the maml base never enters maml.py."""
    return jax.tree.map(lambda x: jnp.broadcast_to(x, (num_lanes,) + x.shape), tree)


def with_encoder_lstm_kernels(params: Mapping[str, Any], kernels: LSTMKernels) -> dict:
    """`params` with the encoder LSTM's parameters replaced by `kernels` (their `update`
    added in, see `LSTMKernels.dense`)."""
    flat = traverse_util.flatten_dict(params)
    cell = traverse_util.flatten_dict(lstm_params(kernels))
    flat.update({ENCODER_LSTM_PATH + path: x for path, x in cell.items()})
    return traverse_util.unflatten_dict(flat)


class LowRankUpdate(NamedTuple):
    """A change of rank R of both kernels with one shared right factor: the input kernel
    plus `inputs^T deltas`, the recurrent kernel plus `hiddens^T deltas`.

    An SGD step on the kernels over a few steps is one: their gradients are
    `sum_t x_t^T delta_t` and `sum_t h_{t-1}^T delta_t`, with delta_t the gradient of step
    t's gate pre-activations (`foresit_jax.maml`'s inner loop keeps its adapted kernels
    so, never as dense copies). A product with the changed kernel is the kernel's product
    plus a rank-R correction, `x K + (x inputs^T) deltas`: the big kernel stays shared
    (unbatched) when every lane has its own update."""

    inputs: chex.Array  # [R, F]
    hiddens: chex.Array  # [R, H]
    deltas: chex.Array  # [R, 4H]

    def concat(self, other: "LowRankUpdate") -> "LowRankUpdate":
        """The sum of two updates (their rows stacked)."""
        return LowRankUpdate(*(jnp.concatenate([a, b], axis=-2) for a, b in zip(self, other)))


class LSTMKernels(NamedTuple):
    input_kernel: chex.Array  # [F, 4H] (ii, if, ig, io)
    recurrent_kernel: chex.Array  # [H, 4H] (hi, hf, hg, ho)
    bias: chex.Array  # [4H]
    recurrent_kernel_t: Optional[chex.Array] = None  # [4H, H]: see `with_transposed_recurrent_kernel`
    update: Optional[LowRankUpdate] = None  # added to both kernels (see LowRankUpdate); None: none

    def dense(self) -> "LSTMKernels":
        """The same kernels with the update added into them (`update` None)."""
        if self.update is None:
            return self
        u = self.update
        return self._replace(
            input_kernel=self.input_kernel + jnp.swapaxes(u.inputs, -1, -2) @ u.deltas,
            recurrent_kernel=self.recurrent_kernel + jnp.swapaxes(u.hiddens, -1, -2) @ u.deltas,
            recurrent_kernel_t=None,
            update=None,
        )


def lstm_kernels(lstm_params: Mapping[str, Any]) -> LSTMKernels:
    """The concatenated kernels of an `nn.OptimizedLSTMCell`'s parameters (its `params`
    subtree, e.g. `encoder_lstm_params(params)`)."""
    return LSTMKernels(
        jnp.concatenate([lstm_params["i" + g]["kernel"] for g in LSTM_GATES], axis=-1),
        jnp.concatenate([lstm_params["h" + g]["kernel"] for g in LSTM_GATES], axis=-1),
        jnp.concatenate([lstm_params["h" + g]["bias"] for g in LSTM_GATES], axis=-1),
    )


def lstm_params(kernels: LSTMKernels) -> dict[str, Any]:
    """The inverse of `lstm_kernels`: the cell's parameter subtree (flax's names) of
    concatenated kernels (`update` added in, see `LSTMKernels.dense`)."""
    kernels = kernels.dense()
    hidden = kernels.recurrent_kernel.shape[-2]
    split = lambda x: jnp.split(x, [hidden, 2 * hidden, 3 * hidden], axis=-1)  # noqa: E731
    out = {}
    for g, ik, hk, b in zip(
        LSTM_GATES, split(kernels.input_kernel), split(kernels.recurrent_kernel), split(kernels.bias)
    ):
        out["i" + g] = {"kernel": ik}
        out["h" + g] = {"kernel": hk, "bias": b}
    return out


def materialized_transpose(kernel: chex.Array) -> chex.Array:
    """`kernel.T` as an array of its own (XLA may not fold it back into a matmul).

    XLA:CPU runs `g @ kernel.T` (a dot contracting both operands' last axes: what
    autodiff emits for the input gradient of `x @ kernel`) much slower than a plain
    matmul (docs/design.md, 'Speed'); with the transpose materialised once, every such
    product is a plain matmul."""
    return jax.lax.optimization_barrier(jnp.transpose(kernel))


@jax.custom_vjp
def dot_with_transposed_kernel(x: chex.Array, kernel: chex.Array, kernel_t: chex.Array) -> chex.Array:
    """`jnp.dot(x, kernel)`, whose gradient for x is `g @ kernel_t` (kernel_t = the
    `materialized_transpose` of kernel; it gets no gradient of its own, kernel gets all)."""
    return jnp.dot(x, kernel)


def _dot_with_transposed_kernel_fwd(x, kernel, kernel_t):
    return jnp.dot(x, kernel), (x, kernel_t)


def _dot_with_transposed_kernel_bwd(residuals, g):
    x, kernel_t = residuals
    x_2d, g_2d = x.reshape(-1, x.shape[-1]), g.reshape(-1, g.shape[-1])
    return jnp.dot(g, kernel_t), jnp.dot(x_2d.T, g_2d), jnp.zeros_like(kernel_t)


dot_with_transposed_kernel.defvjp(_dot_with_transposed_kernel_fwd, _dot_with_transposed_kernel_bwd)


def with_transposed_recurrent_kernel(kernels: LSTMKernels) -> LSTMKernels:
    """Kernels whose `lstm_step` differentiates with plain matmuls (same values; for an
    unroll that is differentiated, the transpose made once outside the loop)."""
    return kernels._replace(recurrent_kernel_t=materialized_transpose(kernels.recurrent_kernel))


def _low_rank_correction(x: chex.Array, rows: chex.Array, deltas: chex.Array) -> chex.Array:
    """`x (rows^T deltas)` as `(x rows^T) deltas`: `[..., D] -> [..., 4H]`."""
    return jnp.dot(jnp.dot(x, jnp.swapaxes(rows, -1, -2)), deltas)


def lstm_input_gates(kernels: LSTMKernels, x: chex.Array) -> chex.Array:
    """The input's contribution to the four gates, `[..., F] -> [..., 4H]`."""
    gates = jnp.dot(x, kernels.input_kernel)
    if kernels.update is not None:
        gates += _low_rank_correction(x, kernels.update.inputs, kernels.update.deltas)
    return gates


def lstm_step(kernels: LSTMKernels, carry: LSTMCarry, input_gates: chex.Array) -> tuple[LSTMCarry, chex.Array]:
    """One step of the cell from its input gates `[..., 4H]` -> ((c, h), h)."""
    c, h = carry
    if kernels.recurrent_kernel_t is None:
        recurrent = jnp.dot(h, kernels.recurrent_kernel)
    else:
        recurrent = dot_with_transposed_kernel(h, kernels.recurrent_kernel, kernels.recurrent_kernel_t)
    if kernels.update is not None:
        recurrent += _low_rank_correction(h, kernels.update.hiddens, kernels.update.deltas)
    recurrent += jnp.reshape(kernels.bias, (1,) * (recurrent.ndim - 1) + (-1,))
    split = np.cumsum([h.shape[-1]] * 3)
    i, f, g, o = (r + x for r, x in zip(jnp.split(recurrent, split, axis=-1), jnp.split(input_gates, split, axis=-1)))
    i, f, g, o = nn.sigmoid(i), nn.sigmoid(f), jnp.tanh(g), nn.sigmoid(o)
    new_c = f * c + i * g
    new_h = o * jnp.tanh(new_c)
    return (new_c, new_h), new_h


class EncoderLSTM(nn.OptimizedLSTMCell):
    """The encoder's LSTM: flax's `nn.OptimizedLSTMCell` (its parameters and its
    `__call__`, unchanged) with the split fast path of this module as its methods: what
    the agent computes with the cell inside its networks goes through it (the maml base
    reads and writes the kernels in a parameter tree with this module's tree functions).

    kernels(update) -> its concatenated kernels (`LSTMKernels`), with a low-rank `update`
      (the maml base's adapted kernels) or None;
    input_gates(x, kernels) -> the input's part of the gates `[..., 4H]`, for any number of
      steps at once;
    unroll(kernels, carry, gates, first) -> the recurrent part over a window of input
      gates `[T, B, 4H]`, the carry zeroed before each step that starts an episode
      (`first` `[T, B]`) (`ActorCritic.encode` over a window: the loss);
    step(kernels, carry, gates) -> one recurrent step from a step's input gates
      (`ActorCritic.encode` at T = 1: acting, on `kernels` made once per window).
    Nothing else in the package calls `lstm_step`: the cell owns its recurrence."""

    # flax's orthogonal initialiser, drawn a sample at a time under vmap (see `layers.orthogonal`)
    recurrent_kernel_init: Any = orthogonal()

    def kernels(self, update: Optional[LowRankUpdate] = None) -> LSTMKernels:
        return lstm_kernels(self.variables["params"])._replace(update=update)

    def input_gates(self, x: chex.Array, kernels: LSTMKernels) -> chex.Array:
        return lstm_input_gates(kernels, x)

    def step(self, kernels: LSTMKernels, carry: LSTMCarry, gates: chex.Array) -> tuple[LSTMCarry, chex.Array]:
        return lstm_step(kernels, carry, gates)

    def unroll(
        self, kernels: LSTMKernels, carry: LSTMCarry, gates: chex.Array, first: chex.Array
    ) -> tuple[LSTMCarry, chex.Array]:
        """(the carry after a window, its states `[T, ..., H]`) from the window's input gates
        `[T, ..., 4H]`, the carry zeroed before each step that begins an episode (`first`
        `[T, ...]`), the recurrent kernel transposed once (`with_transposed_recurrent_kernel`:
        the loss differentiates the unroll)."""
        kernels = with_transposed_recurrent_kernel(kernels)

        def step(carry, step_xs):
            input_gates, first_t = step_xs
            return lstm_step(kernels, reset_carry(first_t, carry), input_gates)

        return jax.lax.scan(step, carry, (gates, first))


def initial_carry(batch_shape, hidden_size: int = 512) -> LSTMCarry:
    """Zero LSTM carry (c, h), each `[*batch_shape, hidden_size]`."""
    zeros = jnp.zeros((*batch_shape, hidden_size), jnp.float32)
    return (zeros, zeros)


def reset_carry(done: chex.Array, carry: LSTMCarry) -> LSTMCarry:
    """Zero the carry where `done` `[...]` is true (use the PREVIOUS step's done)."""
    return jax.tree.map(lambda x: jnp.where(done[..., None], jnp.zeros_like(x), x), carry)
