"""ForeSIT's imagination in one module, in the paper's order: what i_tau is at each step of
acting (Eq. 6-7, and every variant beside the paper's), the sub-goal its critic selects
(Section 4.2), the buffers and f_w's training (Eq. 5, Algorithm 1), and imagination as a
training target (the auxiliary heads, issue 79).

Everything is a pure function over explicit pytrees. Per-lane structures are written
unbatched (one env lane = one A3C agent) and stacked over lanes with `jax.vmap`
(`jax.vmap(buffer_add)(buffers, ...)`), except `train_full_buffers`, which takes the
stacked buffers `[B, M, ...]` because lanes update the shared f_w one after another.

What the rest of the package calls (nothing here imports the modules that call it:
`networks.build` hands this module an `Imagination` record, the variant, f_w's apply, the
noise settings and an encode function for the goal view):

* acting, at every step (`rollout.agent_step`, after the encoder gave s_t): `at_step(...) ->
  (i_tau, ImaginationCarry)`; the encoder's i_tau before that (`encoder_input`); after the
  environment's step, `record_outcomes` (each ended episode's outcome, rho of Eq. 7);
* training, once per update, after the gradient step (`Trainer.update`): `learn(...)`, the
  sub-goals of the window's successful episodes into the buffers and full buffers into f_w;
* training's loss, for an auxiliary target (`train.loss_and_grad_with_target`):
  `target_labels`, `target_window_loss`.

How the f_w update is wired (`learn`, at every step of a window, in time order):
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

import dataclasses
from typing import TYPE_CHECKING, Any, Callable, Mapping, NamedTuple, Optional

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp
import optax

from envs.wrappers import CUES, CueWrapper, GoalViewWrapper
from foresit_jax.layers import Dense
from foresit_jax.methods import ImaginationVariant

if TYPE_CHECKING:  # the targets read a Config's fields; importing config would put this module a floor higher
    from foresit_jax.config import Config


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


# ---------------------------------------------------------------------- i_tau at each step (Eq. 6-7)


@dataclasses.dataclass(frozen=True, eq=False)
class Imagination:
    """What acting and training need of a Config's imagination, handed over by
    `networks.build` (`Networks.imagination`), so that this module calls into no module
    above it. Compared by identity (a jitted function built on one is compiled for it alone).

    goal_latent: `(params, kernels, obs) -> [B, H]`, the agent's own latent of its episodes'
    goal views (the encoder and one LSTM step from a fresh carry on
    `GoalViewWrapper.goal_of(obs)`; `Networks.goal_latent`), called only where i_tau is
    renewed from the goal view; permute: a reordering of the lanes applied to i_tau's inputs
    (the probe's shuffle, `experiments.analysis.probes.shuffled`; None: none)."""

    variant: ImaginationVariant
    imagine: ImagineFn  # f_w's apply, (w, s, goal) -> [..., H]
    goal_latent: Callable
    optimizer: optax.GradientTransformation  # f_w's lane-local optimiser (`make_imagination_optimizer`)
    hidden_size: int
    sigma2_max: float  # Eq. 7
    noise: str  # where Eq. 6's noise is added: 'output' (the paper's) or 'input' (Algorithm 1's)
    rnd_variance: float  # the `rnd` ablation's
    int_interval: int  # the `int` ablation's K
    in_encoder: bool  # i_tau enters the encoder (`Config.imagination_input='encoder'`)
    epochs: int  # f_w's epochs over a full buffer
    batch: int  # items per f_w step
    permute: Optional[Callable] = None


class ImaginationCarry(NamedTuple):
    """What imagination carries per lane from one step to the next (leaves `[B, ...]`)."""

    imagined: chex.Array  # [B, H] the running episode's i_tau
    s_0: chex.Array  # [B, H] the running episode's first state
    tracker: "SuccessTracker"  # [B, window] outcomes of each lane's last episodes (rho of Eq. 7)


def carry_init(num_lanes: int, hidden_size: int, success_window: int, tracker=None) -> ImaginationCarry:
    """Zeros, and fresh success trackers unless `tracker` (`[B, window]`) is kept."""
    zeros = jnp.zeros((num_lanes, hidden_size), jnp.float32)
    if tracker is None:
        one = tracker_init(success_window)
        tracker = jax.tree.map(lambda x: jnp.broadcast_to(x, (num_lanes,) + x.shape), one)
    return ImaginationCarry(zeros, zeros, tracker)


def acting_env(spec: Imagination, env):
    """The environment an imagination acts in: `env` itself, or, for one that reads the goal
    view (the privileged `oracle`) or a cue (`optaction`, `compass`, `startcompass`), `env`
    wrapped to carry it (`envs.wrappers.GoalViewWrapper`, `envs.wrappers.CueWrapper`;
    built for those methods alone, so no other program changes)."""
    variant = spec.variant
    if variant.reads_cue and not isinstance(env, CueWrapper):
        return CueWrapper(env, variant.cue)
    if not variant.reads_goal_view or isinstance(env, GoalViewWrapper):
        return env
    return GoalViewWrapper(env)


def cue_latent(spec: Imagination, obs) -> chex.Array:
    """A privileged cue as i_tau `[B, H]`: `obs["cue"]` `[B, K]` zero-padded to H, exact
    (no noise; `Config` requires sigma2_max=0), lanes reordered by `spec.permute`."""
    cue = obs["cue"]
    cue = (spec.permute or (lambda x: x))(cue)
    return jnp.pad(cue, [(0, 0)] * (cue.ndim - 1) + [(0, spec.hidden_size - cue.shape[-1])])


def encoder_input(spec: Imagination, carry: ImaginationCarry, episode_step: chex.Array, obs) -> Optional[chex.Array]:
    """The i_tau the encoder sees at the lanes' next step `[B, H]`: the running episode's,
    zeros at an episode's first step (i_tau is imagined from that step's output); None
    unless i_tau enters the encoder. A cue is read from the observation, which exists
    before the step's state: the encoder sees the step's own cue, at the first step too."""
    if not spec.in_encoder:
        return None
    if spec.variant.reads_cue:
        return cue_latent(spec, obs)
    return jnp.where((episode_step == 0)[:, None], 0.0, carry.imagined)


def imagine(spec: Imagination, w_params, s_t, goal, key, noise_variance, goal_latent_fn) -> chex.Array:
    """i_tau `[B, H]` from its source (the ImaginationVariant piece), stop-gradient (the
    policy loss never trains f_w or, through it, s_0). learned: f_w([s_t : g]) +
    N(0, sigma2) (Eq. 6), or with `noise='input'` f_w([s_t : g] + N(0, sigma2))
    (Algorithm 1); random: tanh(N(0, v)); goal_view: the goal view's latent + N(0, sigma2).
    `spec.permute` reorders the lanes of i_tau's inputs (the probe's shuffle)."""
    source = spec.variant.source
    permute = spec.permute or (lambda x: x)
    if source == "random":
        return random_imagination(key, s_t.shape, spec.rnd_variance)
    if source == "goal_view":
        return jax.lax.stop_gradient(add_imagination_noise(key, permute(goal_latent_fn()), noise_variance))
    s_t, goal = permute(s_t), permute(goal)
    if spec.noise == "input":
        s_in, goal_in = add_input_noise(key, jax.lax.stop_gradient(s_t), goal, noise_variance)
        return jax.lax.stop_gradient(spec.imagine(w_params, s_in, goal_in))
    imagined = spec.imagine(w_params, jax.lax.stop_gradient(s_t), goal)
    return jax.lax.stop_gradient(add_imagination_noise(key, imagined, noise_variance))


def renews(variant: ImaginationVariant, episode_step: chex.Array, interval: int) -> chex.Array:
    """Whether i_tau is (re)imagined at this step of the episode, `[...]` bool: at every
    `interval`-th step with the `int` ablation's `renew_every_k`, else at the first."""
    if variant.renew_every_k:
        return episode_step % interval == 0
    return episode_step == 0


def at_step(
    spec: Imagination,
    acting,
    kernels,
    carry: ImaginationCarry,
    s_t: chex.Array,
    episode_step: chex.Array,
    obs,
    key: chex.PRNGKey,
) -> tuple[chex.Array, ImaginationCarry]:
    """i_tau for a step `[B, H]` (Eq. 6-7) and the carry after it (s_0 set at an episode's
    first step). i_tau is renewed where the ImaginationVariant piece says (an episode's first
    step; every K steps for `int`) from s_t (= s_0 at the first step) by f_w
    (`acting.imagination_params`), with noise of each lane's variance
    (`acting.noise_variance` `[B]`, or Eq. 7 from its success tracker), else the running
    episode's; unchanged without imagination; a cue is the step's own, every step.

    acting: the step's `rollout.AgentParams` (params, f_w's w, the noise variance); kernels:
    the encoder LSTM's, for the goal view's latent (called only where i_tau is renewed from
    it); episode_step `[B]`: the step's position in its episode; obs: the step's observations
    (the target g_tau, and the goal view or the cue where the variant reads them)."""
    s_0 = jnp.where((episode_step == 0)[:, None], s_t, carry.s_0)

    def kept(imagined):
        return imagined, carry._replace(imagined=imagined, s_0=s_0)

    variant = spec.variant
    if not variant.uses_imagination:
        return kept(carry.imagined)
    if variant.reads_cue:  # the step's own cue, every step
        return kept(cue_latent(spec, obs))
    variance = acting.noise_variance
    if variance is None:
        variance = noise_variance(jax.vmap(success_rate)(carry.tracker), spec.sigma2_max)
    renew = renews(variant, episode_step, spec.int_interval)  # [B]
    goal = obs["target"]
    goal_latent_fn = None  # the oracle's: computed only where i_tau is renewed
    if variant.reads_goal_view:
        goal_latent_fn = lambda: spec.goal_latent(acting.params, kernels, obs)  # noqa: E731

    def renewed():
        mask = renew[:, None]  # [B, 1], before the imagination (the order of the lowered program's ops)
        imagined = imagine(spec, acting.imagination_params, s_t, goal, key, variance, goal_latent_fn)
        return jnp.where(mask, imagined, carry.imagined)

    return kept(jax.lax.cond(jnp.any(renew), renewed, lambda: carry.imagined))


def record_outcomes(carry: ImaginationCarry, success: chex.Array, finished: chex.Array) -> ImaginationCarry:
    """The carry after a step of the environment: each lane's episode that `finished`
    `[B]` there adds its outcome `success` `[B]` to the lane's tracker (rho, Eq. 7)."""
    return carry._replace(tracker=jax.vmap(tracker_update)(carry.tracker, success, finished))


# ---------------------------------------------------------------------- the sub-goal (Section 4.2)


def subgoals_of_rows(keys: chex.Array, alpha: chex.Array, mode: str = "argmax") -> chex.Array:
    """The sub-goal each attention row would select: `keys [..., K, H]`, `alpha [..., R, K]`
    -> `[..., R, H]` (stop-gradient, targets for f_w): the key with the largest weight
    ('argmax', ForeSIT's s_{t*}, first on ties) or the weighted average
    ('attention_average', the `att` ablation). Masked keys carry alpha = 0."""
    chex.assert_equal_shape_prefix([keys, alpha], keys.ndim - 2)
    keys, alpha = jax.lax.stop_gradient((keys, alpha))
    if mode == "argmax":
        index = jnp.argmax(alpha, axis=-1)  # [..., R]
        return jnp.take_along_axis(keys, index[..., None], axis=-2)  # [..., R, H]
    if mode == "attention_average":
        return jnp.einsum("...rk,...kh->...rh", alpha, keys)
    raise ValueError(f"Unknown sub-goal mode {mode!r}; use 'argmax' or 'attention_average'.")


def subgoal_items(subgoal_mode: str, traj, alpha, key_states, success):
    """What each step of a window (`traj`, a `rollout.Trajectory` recorded with its inputs)
    offers the buffers: (s_0 `[T, B, H]`, g_tau `[T, B, D]`, the sub-goal ŝ_tau `[T, B, H]`,
    add `[T, B]`: an episode ended there successfully). ŝ_tau is what the step's attention
    row selects (Section 4.2: at the Done step, s_{t*}, t* = argmax alpha, over all the
    episode's states); the plain critic has no attention (alpha None), and ŝ_tau is then
    the step's own state, the goal state. subgoal_mode: the ImaginationVariant's ('argmax'
    or 'attention_average')."""
    if alpha is None:
        subgoals = jax.lax.stop_gradient(traj.states)
    else:
        subgoals = jnp.swapaxes(subgoals_of_rows(key_states, alpha[:, :-1], subgoal_mode), 0, 1)
    return traj.s_0, traj.inputs.obs["target"], subgoals, success


def subgoal_steps(episode_step: chex.Array, end_episode_step: chex.Array, alpha) -> chex.Array:
    """Where each step's sub-goal lies in its episode, `[T, B]` int32: t* (the position
    of the key its attention row weighs most; the step's own position with the plain
    critic, whose sub-goal is the step's state). episode_step `[T, B]`: the window's steps'
    positions; end_episode_step `[B]`: the position after it. The keys are the memory,
    positions 0..M-1 of the running episode, then the window's states (`train.window_critic`)."""
    if alpha is None:
        return episode_step
    steps = jnp.concatenate([episode_step, end_episode_step[None]], axis=0).T  # [B, T + 1]
    memory_size = alpha.shape[-1] - steps.shape[-1]
    memory = jnp.broadcast_to(jnp.arange(memory_size, dtype=steps.dtype), (steps.shape[0], memory_size))
    key_steps = jnp.concatenate([memory, steps], axis=1)  # [B, M + T + 1]
    index = jnp.argmax(alpha[:, :-1], axis=-1)  # [B, T]
    return jnp.take_along_axis(key_steps, index, axis=1).T  # [T, B]


# ---------------------------------------------------------------------- f_w's training, once per update


def store_and_train(spec: Imagination, w_params, buffers: ReplayBuffer, items):
    """Algorithm 1 for each step of the window in time order: lanes whose episode
    ended successfully there add (s_0, g_tau, ŝ_tau) to their buffer; full buffers
    train the shared f_w and are emptied. items: (s_0 `[T, B, H]`, goal `[T, B, D]`,
    subgoal `[T, B, H]`, add `[T, B]` bool). Returns (w, buffers, metrics)."""

    def step(carry, item):
        w_params, buffers, losses = carry
        buffers = jax.vmap(buffer_add)(buffers, *item)
        w_params, buffers, trained, _ = train_on_full_buffers(
            w_params, buffers, spec.imagine, spec.optimizer, spec.epochs, spec.batch
        )
        return (w_params, buffers, losses.plus(trained)), None

    carry = (w_params, buffers, ImaginationLosses.zeros())
    (w_params, buffers, losses), _ = jax.lax.scan(step, carry, items)
    return w_params, buffers, losses.metrics()


def learn(spec: Imagination, w_params, buffers: ReplayBuffer, traj, alpha, key_states, success):
    """f_w's part of one update, after the agent's gradient step (Algorithm 1): the sub-goals
    of the window's successful episodes (`subgoal_items`) into the buffers, and full buffers
    into f_w (`store_and_train`). traj: the window (a `rollout.Trajectory`); alpha, key_states:
    the critic's attention rows and keys over it (`train.window_critic`); success `[T, B]`:
    a successful episode ended at the step. Returns (w, buffers, metrics); without a learned
    imagination, the same w and buffers and no metrics."""
    if not spec.variant.trains_imagination:
        return w_params, buffers, {}
    items = subgoal_items(spec.variant.subgoal_mode, traj, alpha, key_states, success)
    return store_and_train(spec, w_params, buffers, items)


# ---------------------------------------------------------------------- imagination as a training target (issue 79)
# A linear head on the recurrent state s_t learns to
# predict a target y_t at every valid step of a window, with weight lambda beside the
# actor-critic loss (`Config.aux_target`, `Config.aux_weight`); nothing of it acts.
#
#     L = L_A3C + lambda * mean over labelled steps of loss(W s_t + b, stop_gradient(y_t))
#
# The head's parameters are a tree of their own (`RunnerState.targets`, beside f_w's), with
# an optimiser of their own (the base's: gradient clipping and Adam at the base's rate), so
# the programs that act and evaluate (`foresit_jax.evaluate`, `foresit_jax.policy`) are the
# base's, and nothing privileged is read at test time. The target reaches the agent only
# through the gradient its loss sends into the encoder, through s_t.
#
# The targets (`config.AUX_TARGETS`), each a documented option:
#
# * ``compass`` (a privileged label in training): the bearing and distance of the nearest
#   target cell from the step's pose, ``(cos b, sin b, d / G)``, as the ``compass`` cue
#   computes them (`envs.wrappers.CueWrapper`, which wraps the training environment alone);
#   squared error, summed over the three components.
# * ``goal_view`` (a privileged label in training): the agent's own latent of the episode's
#   goal view (the `oracle` imagination's i_tau before noise: the encoder and one LSTM step
#   from a fresh carry on the goal view, `envs.wrappers.GoalViewWrapper`), computed in the
#   loss from the parameters of this update (without gradient) at every step: the label
#   follows the encoder as it learns, where a latent computed at the episode's start in
#   acting would be that of the parameters of an earlier update for an episode that began
#   in an earlier window. Smooth-L1 (the paper's f_w loss, `smooth_l1`).
# * ``success`` (not privileged): the agent's own state at the step where its episode
#   succeeded, for the earlier steps of that episode that share the success step's window
#   (the success step itself excluded; steps whose episode failed, or ends after the
#   window, are not labelled). Smooth-L1. `labelled_fraction` is logged every update.
#
# Each is a pure function of a window (`Trajectory`-shaped arrays `[T, B, ...]`); the
# Trainer (`foresit_jax.train.loss_and_grad_with_target`) calls `target_window_loss` from
# its replay loss.

# Whether a target's labels read what the agent cannot see (its wrapper reads the scene).
PRIVILEGED_LABELS: dict[str, bool] = {"compass": True, "goal_view": True, "success": False}


class TargetHead(nn.Module):
    """The linear head: s_t `[..., H]` -> the predicted target `[..., width]`."""

    width: int

    @nn.compact
    def __call__(self, s_t: chex.Array) -> chex.Array:
        return Dense(self.width, name="out")(s_t)


class TargetState(NamedTuple):
    """The head's parameters and their optimiser's state (`RunnerState.targets`)."""

    params: chex.ArrayTree
    opt_state: chex.ArrayTree


class TargetLabels(NamedTuple):
    """What the head learns on one window: `y` `[T, B, width]` (without gradient) and
    `mask` `[T, B]` bool, the steps labelled."""

    y: chex.Array
    mask: chex.Array


def target_width(config: Config) -> int:
    """The target's width: the compass's 3 floats, or a latent's `hidden_size`."""
    return CUES["compass"] if config.aux_target == "compass" else config.hidden_size


def target_head(config: Config) -> TargetHead:
    return TargetHead(target_width(config))


def label_env(config: Config, env):
    """The training environment wrapped to carry the target's labels (`obs["cue"]` for
    ``compass``, `obs["goal_view"]` for ``goal_view``); `env` itself otherwise. Training
    alone acts in it: evaluation builds its own environment, the base's."""
    if config.aux_target == "compass":
        return CueWrapper(env, "compass")
    if config.aux_target == "goal_view":
        return GoalViewWrapper(env)
    return env


def success_labels(states, terminated, truncated, success, valid) -> TargetLabels:
    """`success`'s labels: for each valid step t of a window, the state s_e of the step e
    where its episode ended, where e > t lies in the window and the episode succeeded there.

    A reverse scan over time carries, per lane, the state and outcome of the next episode
    end at or after each step; steps of one episode are contiguous in a lane, so the next
    end is the step's own episode's. states `[T, B, H]`; the rest `[T, B]` bool."""
    ended = (terminated | truncated) & valid

    def step(carry, x):
        next_state, next_success = carry
        s, end, succ, ok = x
        label, labelled = next_state, next_success & ok & ~end  # the end step itself excluded
        carry = (jnp.where(end[:, None], s, next_state), jnp.where(end, succ, next_success))
        return carry, (label, labelled)

    init = (jnp.zeros_like(states[0]), jnp.zeros(states.shape[1], bool))
    _, (y, mask) = jax.lax.scan(step, init, (states, ended, success & ended, valid), reverse=True)
    return TargetLabels(jax.lax.stop_gradient(y), mask)


def target_labels(config: Config, obs: dict, states, traj, goal_latent: Optional[Callable] = None) -> TargetLabels:
    """The labels of one window for `config.aux_target`; with `config.aux_permute` (the
    content control), lane b learns lane b - 1's labels (labels and mask rolled by one lane).
    obs: the window's recorded observations (leaves `[T, B, ...]`, from the label
    environment); states: s_t `[T, B, H]`; traj: the window's `Trajectory` (terminated,
    truncated, success, valid); goal_latent: `obs -> [N, H]`, the goal view's latent under
    this update's parameters (``goal_view`` only)."""
    labels = _own_labels(config, obs, states, traj, goal_latent)
    if not config.aux_permute:
        return labels
    return TargetLabels(*(jnp.roll(x, 1, axis=1) for x in labels))


def _own_labels(config: Config, obs: dict, states, traj, goal_latent: Optional[Callable]) -> TargetLabels:
    """Each lane's own labels of one window (`target_labels` without the permutation)."""
    target, valid = config.aux_target, traj.valid
    if target == "compass":
        return TargetLabels(obs["cue"], valid)
    if target == "goal_view":
        lead = valid.shape
        flat = jax.tree.map(lambda x: jnp.reshape(x, (-1, *x.shape[len(lead) :])), obs)
        latent = jnp.reshape(goal_latent(flat), (*lead, -1))
        return TargetLabels(jax.lax.stop_gradient(latent), valid)
    if target == "success":
        return success_labels(states, traj.terminated, traj.truncated, traj.success, valid)
    raise ValueError(f"aux_target must be one of {tuple(PRIVILEGED_LABELS)}, got {target!r}")


def target_step_loss(target: str, prediction: chex.Array, y: chex.Array) -> chex.Array:
    """`[T, B]`: the compass's squared error summed over its components, a latent's smooth-L1
    (averaged over its dimensions, as f_w's loss)."""
    y = jax.lax.stop_gradient(y)
    if target == "compass":
        return jnp.sum((prediction - y) ** 2, axis=-1)
    return smooth_l1(prediction, y)


def target_window_loss(
    config: Config, head_params, states: chex.Array, labels: TargetLabels
) -> tuple[chex.Array, dict]:
    """(the mean loss over the labelled steps (0 where none), its metrics). states: s_t
    `[T, B, H]`, differentiable (the gradient reaches the encoder through them)."""
    prediction = target_head(config).apply(head_params, states)
    mask = labels.mask.astype(jnp.float32)
    count = jnp.sum(mask)
    loss = jnp.sum(target_step_loss(config.aux_target, prediction, labels.y) * mask) / jnp.maximum(count, 1.0)
    return loss, {"losses/aux_loss": loss, "charts/aux_labelled": count}


def target_init(config: Config, key: chex.PRNGKey, optimizer) -> Optional[TargetState]:
    """The head's initial TargetState (None without a target)."""
    if config.aux_target == "none":
        return None
    params = target_head(config).init(key, jnp.zeros((config.hidden_size,), jnp.float32))
    return TargetState(params, optimizer.init(params))
