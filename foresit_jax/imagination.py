"""Learning to imagine (Section 4.3, Eq. 5-7, Algorithm 1): per-lane replay buffers,
the f_w update, per-lane success rates and the imagination noise.

Everything is a pure function over explicit pytrees. Per-lane structures are written
unbatched (one env lane = one A3C agent) and stacked over lanes with `jax.vmap`
(`jax.vmap(buffer_add)(buffers, ...)`), except `train_full_buffers`, which takes the
stacked buffers `[B, M, ...]` because lanes update the shared f_w one after another.

How the f_w update is wired (the Trainer calls this at every step of a window, in time
order, `Trainer.store_and_train`):
  1. each lane whose episode ended successfully at that step adds (s_0, g_tau, ŝ_tau) to its buffer
     (`buffer_add`, a no-op for failed episodes);
  2. `train_full_buffers(w_params, buffers, ...)` visits the lanes whose buffer is
     full, in lane order. Each such lane copies the CURRENT shared parameters (including
     what earlier lanes pushed in this same call), trains them `epochs` epochs over its
     M items, one item per optimiser step in buffer order (Algorithm 1's inner loop),
     with a fresh optimiser state (the lane's own optimiser), and writes the result back
     as the new shared parameters (A3C-style push). Its buffer is then emptied.
     This equals a scan over all lanes that selects (`jnp.where`) the trained parameters
     where the buffer is full, but runs only the full lanes: a `lax.while_loop` over the
     full lanes' indices (its trip count is the number of full lanes; under a vmap over
     seeds, the largest such number), since training every lane and discarding most
     would cost B * epochs * M optimiser steps every update.
"""

from __future__ import annotations

from typing import Any, Callable, Mapping, NamedTuple

import chex
import jax
import jax.numpy as jnp
import optax


# apply_fn(params, s_0 [..., H], goal [..., D]) -> imagined state [..., H]
ImagineFn = Callable[[Any, chex.Array, chex.Array], chex.Array]


class ReplayBuffer(NamedTuple):
    """One lane's buffer M of (s_0, g_tau, ŝ_tau) from successful episodes."""

    s_0: chex.Array  # [M, H] initial states
    goal: chex.Array  # [M, D] target embeddings g_tau
    subgoal: chex.Array  # [M, H] selected sub-goals ŝ_tau
    count: chex.Array  # [] int32, number of items filled (0..M)

    @property
    def capacity(self) -> int:
        return self.s_0.shape[-2]


def smooth_l1(prediction: chex.Array, target: chex.Array, beta: float = 1.0) -> chex.Array:
    """Smooth-L1 (Huber with threshold `beta`), averaged over the last axis.

    Per element: 0.5 * x**2 / beta if |x| < beta else |x| - 0.5 * beta, x = prediction -
    target. For one item `[D]` this equals `torch.nn.SmoothL1Loss()(prediction, target)`
    (reduction='mean' over all D dims, beta=1); `[..., D] -> [...]`, so the mean over a
    batch of items is the mean of the result (also torch's value on the whole batch).
    """
    chex.assert_equal_shape([prediction, target])
    x = jnp.abs(prediction - target)
    elementwise = jnp.where(x < beta, 0.5 * x**2 / beta, x - 0.5 * beta)
    return jnp.mean(elementwise, axis=-1)


def buffer_init(capacity: int, state_size: int, goal_size: int) -> ReplayBuffer:
    """An empty buffer with room for `capacity` (M_max) items."""
    return ReplayBuffer(
        s_0=jnp.zeros((capacity, state_size), jnp.float32),
        goal=jnp.zeros((capacity, goal_size), jnp.float32),
        subgoal=jnp.zeros((capacity, state_size), jnp.float32),
        count=jnp.zeros((), jnp.int32),
    )


def buffer_add(
    buffer: ReplayBuffer,
    s_0: chex.Array,
    goal: chex.Array,
    subgoal: chex.Array,
    is_success: chex.Array,
) -> ReplayBuffer:
    """Append one item if `is_success` (and the buffer is not already full).

    s_0 `[H]`, goal `[D]`, subgoal `[H]`, is_success `[]` bool. A full buffer drops new
    items; with `train_full_buffers` run after every add this never happens.
    """
    chex.assert_shape(s_0, buffer.s_0.shape[-1:])
    chex.assert_shape(goal, buffer.goal.shape[-1:])
    chex.assert_shape(subgoal, buffer.subgoal.shape[-1:])
    write = jnp.logical_and(is_success, buffer.count < buffer.capacity)
    index = jnp.minimum(buffer.count, buffer.capacity - 1)

    def put(store, item):
        return store.at[index].set(jnp.where(write, item, store[index]))

    return ReplayBuffer(
        s_0=put(buffer.s_0, s_0),
        goal=put(buffer.goal, goal),
        subgoal=put(buffer.subgoal, subgoal),
        count=buffer.count + write.astype(jnp.int32),
    )


def buffer_is_full(buffer: ReplayBuffer) -> chex.Array:
    """`[]` bool (or `[B]` on stacked buffers): |M| = M_max."""
    return buffer.count >= buffer.capacity


def buffer_clear(buffer: ReplayBuffer) -> ReplayBuffer:
    """M = empty set (contents zeroed too, so an emptied buffer equals a fresh one)."""
    return jax.tree.map(jnp.zeros_like, buffer)


def imagination_loss(
    apply_fn: ImagineFn, params: Any, s_0: chex.Array, goal: chex.Array, subgoal: chex.Array
) -> chex.Array:
    """Eq. 5 with smooth-L1: mean over items `[..., H]` of smooth_l1(f_w([s_0 : g]), ŝ)."""
    imagined = apply_fn(params, s_0, goal)
    return jnp.mean(smooth_l1(imagined, jax.lax.stop_gradient(subgoal)))


def make_imagination_optimizer(name: str, learning_rate: float) -> optax.GradientTransformation:
    """The lane-local f_w optimiser: 'sgd' (Algorithm 1's plain step) or 'adam'."""
    if name == "sgd":
        return optax.sgd(learning_rate)
    if name == "adam":
        return optax.adam(learning_rate)
    raise ValueError(f"Unknown imagination optimizer {name!r}; use 'sgd' or 'adam'.")


def train_on_buffer(
    params: Any,
    buffer: ReplayBuffer,
    apply_fn: ImagineFn,
    optimizer: optax.GradientTransformation,
    epochs: int,
    batch: int = 1,
    opt_state: Any = None,
) -> tuple[Any, chex.Array, Any]:
    """Train f_w on one full buffer: `epochs` passes, one optimiser step per item (per
    `batch` consecutive items, their mean loss), in buffer order (Algorithm 1 with batch
    1), starting from `params` with `opt_state` (None: a fresh optimiser state, as
    training does at every flush).

    Returns (trained params, per-step losses `[epochs, M / batch]`, each the loss before
    its step, the optimiser state after the last step).
    """
    grad_fn = jax.value_and_grad(lambda p, s0, g, sg: imagination_loss(apply_fn, p, s0, g, sg))
    items = (buffer.s_0, buffer.goal, buffer.subgoal)  # each [M, ...]
    if batch > 1:  # [M / batch, batch, ...]: the loss is the batch's mean (batch 1 keeps Algorithm 1's program)
        items = jax.tree.map(lambda x: x.reshape((x.shape[0] // batch, batch) + x.shape[1:]), items)

    def item_step(carry, item):
        params, opt_state = carry
        loss, grads = grad_fn(params, *item)
        updates, opt_state = optimizer.update(grads, opt_state, params)
        return (optax.apply_updates(params, updates), opt_state), loss

    def epoch(carry, _):
        return jax.lax.scan(item_step, carry, items)

    start = optimizer.init(params) if opt_state is None else opt_state
    (params, opt_state), step_losses = jax.lax.scan(epoch, (params, start), None, length=epochs)
    return params, step_losses, opt_state


class ImaginationLosses(NamedTuple):
    """f_w's training losses summed over the lanes it trained on, so that any number of
    `train_on_full_buffers` calls (one per step of a window) add up before one mean."""

    trained: chex.Array  # [] float32, lanes whose full buffer f_w trained on
    loss: chex.Array  # [] the sum over them of each lane's mean loss (all epochs)
    first_epoch: chex.Array  # [] ... of its first epoch
    last_epoch: chex.Array  # [] ... of its last epoch

    @classmethod
    def zeros(cls) -> "ImaginationLosses":
        zero = jnp.zeros((), jnp.float32)
        return cls(zero, zero, zero, zero)

    def plus(self, other: "ImaginationLosses") -> "ImaginationLosses":
        return ImaginationLosses(*(a + b for a, b in zip(self, other)))

    def metrics(self) -> dict[str, chex.Array]:
        """`imagination/num_trained_lanes` and, averaged over the trained lanes (0 if
        none), `imagination/loss`, `imagination/first_epoch_loss`, `imagination/last_epoch_loss`."""
        denominator = jnp.maximum(self.trained, 1.0)
        return {
            "imagination/num_trained_lanes": self.trained,
            "imagination/loss": self.loss / denominator,
            "imagination/first_epoch_loss": self.first_epoch / denominator,
            "imagination/last_epoch_loss": self.last_epoch / denominator,
        }


def train_on_full_buffers(
    w_params: Any,
    buffers: ReplayBuffer,
    apply_fn: ImagineFn,
    optimizer: optax.GradientTransformation,
    epochs: int,
    batch: int = 1,
    opt_state: Any = None,
) -> tuple[Any, ReplayBuffer, ImaginationLosses, Any]:
    """Update the shared f_w from every lane whose buffer is full, then empty those
    (`train_on_buffer` with `batch` items a step). With `opt_state` None (training's
    procedure) each lane's buffer starts a fresh optimiser state; given, one state is
    carried from lane to lane and returned, for an optimiser kept across flushes
    (`experiments.analysis.probes.replay_online_fit` measures it; training does not offer it).

    Args:
      w_params: the shared f_w parameters.
      buffers: stacked per-lane buffers, leaves `[B, M, ...]`, count `[B]`.
    Returns:
      (new shared params, buffers with the full ones emptied, the losses summed over the
      trained lanes, the optimiser state carried: None when none was given). See the
      module docstring for the order and semantics.
    """
    full = buffer_is_full(buffers)  # [B]
    num_lanes = full.shape[0]
    num_full = jnp.sum(full.astype(jnp.int32))
    # Full lanes first, in lane order (stable sort on "not full").
    order = jnp.argsort(jnp.logical_not(full).astype(jnp.int32), stable=True)  # [B]
    zero = jnp.zeros((), jnp.float32)

    def cond(carry):
        i = carry[0]
        return i < num_full

    kept = opt_state is not None

    def body(carry):
        i, params, state, loss_sum, first_sum, last_sum = carry
        lane = jax.tree.map(lambda x: x[order[i]], buffers)
        params, step_losses, state_after = train_on_buffer(params, lane, apply_fn, optimizer, epochs, batch, state)
        return (
            i + 1,
            params,
            state_after if kept else None,  # None: no leaf, the loop of a fresh state per flush
            loss_sum + jnp.mean(step_losses),
            first_sum + jnp.mean(step_losses[0]),
            last_sum + jnp.mean(step_losses[-1]),
        )

    _, params, opt_state, loss_sum, first_sum, last_sum = jax.lax.while_loop(
        cond, body, (jnp.zeros((), jnp.int32), w_params, opt_state, zero, zero, zero)
    )
    cleared = jax.vmap(buffer_clear)(buffers)
    buffers = jax.tree.map(
        lambda new, old: jnp.where(full.reshape((num_lanes,) + (1,) * (old.ndim - 1)), new, old),
        cleared,
        buffers,
    )
    return params, buffers, ImaginationLosses(num_full.astype(jnp.float32), loss_sum, first_sum, last_sum), opt_state


def train_full_buffers(
    w_params: Any,
    buffers: ReplayBuffer,
    apply_fn: ImagineFn,
    optimizer: optax.GradientTransformation,
    epochs: int,
) -> tuple[Any, ReplayBuffer, Mapping[str, chex.Array]]:
    """`train_on_full_buffers` with its losses as metrics (`ImaginationLosses.metrics`)."""
    params, buffers, losses, _ = train_on_full_buffers(w_params, buffers, apply_fn, optimizer, epochs)
    return params, buffers, losses.metrics()


class SuccessTracker(NamedTuple):
    """One lane's ring of its last `window` episode outcomes (for rho, Eq. 7)."""

    outcomes: chex.Array  # [window] float32, 1.0 success / 0.0 failure
    next_index: chex.Array  # [] int32, slot the next outcome goes to
    count: chex.Array  # [] int32, filled slots (0..window)


def tracker_init(window: int = 100) -> SuccessTracker:
    return SuccessTracker(
        outcomes=jnp.zeros((window,), jnp.float32),
        next_index=jnp.zeros((), jnp.int32),
        count=jnp.zeros((), jnp.int32),
    )


def tracker_update(tracker: SuccessTracker, success: chex.Array, finished: chex.Array = True) -> SuccessTracker:
    """Record one episode outcome `success` `[]` if `finished` `[]` (else unchanged)."""
    window = tracker.outcomes.shape[-1]
    finished = jnp.asarray(finished, bool)
    slot = tracker.outcomes[tracker.next_index]
    outcomes = tracker.outcomes.at[tracker.next_index].set(jnp.where(finished, jnp.asarray(success, jnp.float32), slot))
    step = finished.astype(jnp.int32)
    return SuccessTracker(
        outcomes=outcomes,
        next_index=(tracker.next_index + step) % window,
        count=jnp.minimum(tracker.count + step, window),
    )


def success_rate(tracker: SuccessTracker) -> chex.Array:
    """rho: mean outcome over the filled slots (the last min(count, window) episodes);
    0.0 before any episode. Unfilled slots hold 0, so the sum over all slots is exact."""
    total = jnp.sum(tracker.outcomes, axis=-1)
    return total / jnp.maximum(tracker.count, 1).astype(jnp.float32)


def noise_variance(success_rate: chex.Array, sigma2_max: float = 0.9) -> chex.Array:
    """Eq. 7: sigma^2 = max(sigma^2_max - rho, 0)."""
    return jnp.maximum(sigma2_max - success_rate, 0.0)


def add_imagination_noise(key: chex.PRNGKey, imagined: chex.Array, variance: chex.Array) -> chex.Array:
    """Eq. 6: i_tau = f_w([s_0 : g_tau]) + eta, eta ~ N(0, sigma^2 I).

    imagined `[..., H]`, variance `[...]` (per lane) -> `[..., H]`.
    """
    chex.assert_equal_shape_prefix([imagined, variance], variance.ndim)
    eta = jax.random.normal(key, imagined.shape, imagined.dtype)
    return imagined + jnp.sqrt(variance)[..., None] * eta


def add_input_noise(
    key: chex.PRNGKey, s_0: chex.Array, goal: chex.Array, variance: chex.Array
) -> tuple[chex.Array, chex.Array]:
    """Algorithm 1's placement: f_w's input [s_0 : g_tau] + eta, eta ~ N(0, sigma^2 I) over its
    H + D dimensions (one draw, split back into the two parts).

    s_0 `[..., H]`, goal `[..., D]`, variance `[...]` (per lane) -> (s_0, goal) with the noise.
    """
    chex.assert_equal_shape_prefix([s_0, goal, variance], variance.ndim)
    h = s_0.shape[-1]
    eta = jax.random.normal(key, s_0.shape[:-1] + (h + goal.shape[-1],), s_0.dtype) * jnp.sqrt(variance)[..., None]
    return s_0 + eta[..., :h], goal + eta[..., h:]


def random_imagination(key: chex.PRNGKey, shape: tuple[int, ...], variance: float = 0.5) -> chex.Array:
    """The `rnd` ablation: i_tau = tanh(z), z ~ N(0, variance I) (variance 0.5)."""
    return jnp.tanh(jnp.sqrt(variance) * jax.random.normal(key, shape, jnp.float32))
