"""SAVN's self-adaptive learner (the `maml` base): a learned interaction loss L_phi, inner
SGD steps on it inside every episode, and an exact second-order meta-gradient.

Read from allenai/savn (models/savn.py, models/tcn.py, runners/savn_train.py,
runners/train_util.py, runners/savn_val.py, agents/agent.py) and kept as it is there:

* After every step the agent records [h_t : pi_t] (the LSTM output and the action
  probabilities of that step, H + A values; nothing detached). `LearnedLoss` reads the
  last `segment` (6) of them as a `[6, H + A]` block whose 6 steps are the CHANNELS of a
  1-d convolution that slides over the H + A features (SAVN's `ll_tc`: Conv1d 6->10,
  kernel 2, dilation 1, then 10->1, kernel 2, dilation 2, each causal (left zero padding,
  PyTorch's pad-and-chomp) and followed by a leaky ReLU of slope 0.01; no weight norm,
  dropout or residual: SAVN's `TemporalBlock.net` uses its first conv only). L_phi is the
  L2 norm of the `[H + A]` output.
* Inner loop: after steps 6, 12, 18 and 24 of an episode that has not ended (at most
  `maml_inner_updates` = 4), theta_{i+1} = theta_i - 1e-4 grad_theta L_phi(the 6 steps run
  under theta_i), keeping the graph (second order). The gradient is with respect to
  theta_i only: the LSTM carry entering the segment comes from earlier parameters and
  counts as an input, as torch.autograd.grad(..., params_list[i]) does. Every parameter
  adapts except L_phi's own (SAVN skips names containing 'll'); the LSTM carry and the
  previous action probabilities run on across an update unchanged. After the 4th update
  the episode runs to its end with theta_4.
* The meta-loss is the A3C loss of the whole episode, each step under the theta_i current
  at that step, differentiated with respect to theta_0 and phi (phi gets its gradient only
  through the inner updates). The trainer computes it with `gradient='through_rollout'`:
  the inner `jax.grad` runs inside the acting scan's segments and the outer gradient goes
  through it (exact second order; `Config.maml_first_order` stops the inner gradient's
  own gradient, MAML's first-order approximation, off by default).
* Test time runs the same inner loop (`rollout.rollout` calls the same `adaptive_act`), with
  no meta-step; actions are sampled (SAVN's validation samples too).

Adapted kernels. Each lane adapts its own theta_i, but the encoder LSTM's two kernels (the
input kernel alone is `[F, 4H]`, 25 MB at the paper's sizes) are never copied per lane:
their inner gradient over a segment is sum_t x_t^T delta_t (input kernel) and
sum_t h_{t-1}^T delta_t (recurrent kernel), with x_t the LSTM's input, h_{t-1} its carry
and delta_t the gradient of L_phi with respect to step t's gate pre-activations (taken as
the gradient of a zero offset added to them). So after i updates a lane's kernels are
theta_0's plus an update of rank <= 6 i (`lstm.LowRankUpdate`: the recorded x_t and
h_{t-1}, and -lr delta_t), and a step's gates are x W_0 + (x X^T) D: one matmul with the
shared W_0 for all lanes plus a small per-lane correction. This is the same function, not an
approximation (second order included: the factors are differentiable functions of theta_0
and phi); it only changes how theta_i is stored (`AdaptedParams`; `dense()` builds the
lanes' whole trees). The other parameters (about 170 thousand at the paper's sizes) are
per-lane copies.

Choices where SAVN's code leaves one open or where ours differs, each with its reason:

* Values (the critic) are computed under theta_0's critic parameters. This is exact, not
  an approximation: L_phi reads h_t and pi_t only, so its gradient with respect to the
  critic is zero and every theta_i carries theta_0's critic (SAVN's critic_linear likewise
  gets no inner gradient). The same holds for ForeSIT's attention critic.
* A3C+MAML+ForeSIT: i_tau = f_w([s_0 : g_tau]) is imagined at the episode's first step,
  from s_0 computed under theta_0 (no update has happened yet) and with f_w's own
  parameters w, which never adapt: f_w is trained by its buffers (Algorithm 1), not by
  the meta-gradient, and the policy's loss never reaches w (i_tau is a stop-gradient
  input). The policy head's weights on i_tau adapt like the rest of the policy.
* The norm is sqrt(sum x^2 + 1e-12): SAVN's plain sqrt has an infinite gradient at 0.
* The optimiser is the trainer's (Adam with the config's learning rate and global-norm
  clipping), shared with every other method so that comparisons differ in the method
  only; SAVN's SharedAdam (AMSGrad, eps 1e-3, no clipping) is not reproduced.
* Lanes are SAVN's workers: each lane adapts its own parameters (vmapped over lanes; the
  LSTM's kernels as low-rank updates, see "Adapted kernels"), and one meta-update takes
  the A3C loss's mean over all lanes' valid steps (the synchronous stand-in for SAVN's
  asynchronous one-episode gradients; a longer episode weighs more, as in the other
  methods' whole-episode updates).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, NamedTuple, Optional

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp
from flax import traverse_util

from foresit_jax import distributions
from foresit_jax.lstm import (
    LowRankUpdate,
    encoder_lstm_params,
    join_partial_trees,
    lane_copies,
    lstm_kernels,
    split_encoder_lstm_kernels,
    with_encoder_lstm_kernels,
)

LEARNED_LOSS_SCOPE = "learned_loss"  # params["params"]["learned_loss"]: phi


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


def interaction_inputs(states: chex.Array, logits: chex.Array) -> chex.Array:
    """[h_t : pi_t] per step, `[..., H + A]` (what L_phi reads)."""
    return jnp.concatenate([states, distributions.probs(logits)], axis=-1)


def adapts(path: tuple[str, ...]) -> bool:
    """Whether the inner loop adapts the parameter at `path` (everything but phi)."""
    return LEARNED_LOSS_SCOPE not in path


def inner_step(params, grads, lr: float, apply: chex.Array = True):
    """theta - lr * grad on every adapted leaf (phi is passed through); where `apply` is
    False the parameters are returned unchanged."""
    flat_p = traverse_util.flatten_dict(params)
    flat_g = traverse_util.flatten_dict(grads)
    out = {
        path: jnp.where(apply, p - lr * flat_g[path], p) if adapts(path) else p for path, p in flat_p.items()
    }
    return traverse_util.unflatten_dict(out)


def update_steps(num_steps: int, segment: int, max_updates: int) -> tuple[int, ...]:
    """The episode steps after which an inner update may happen within `num_steps` steps:
    (6, 12, 18, 24) for SAVN's segment 6 and 4 updates; none after the last step (its
    parameters would act no more)."""
    return tuple(segment * (i + 1) for i in range(max_updates) if segment * (i + 1) < num_steps)


class AdaptedParams(NamedTuple):
    """Every lane's parameters after an inner-update slot (theta_i of each lane), kept
    without per-lane copies of the encoder LSTM's kernels (see "Adapted kernels" in the
    module docstring). `dense()` builds the lanes' whole trees."""

    shared: Any  # theta_0's LSTM kernels: the first partial tree of `lstm.split_encoder_lstm_kernels`, unbatched
    lanes: Any  # every other parameter, leaves [B, ...] (phi included, never adapted)
    lstm_update: Optional[LowRankUpdate]  # [B, R, ...] each lane's change of those kernels; None: none yet

    def dense(self):
        """Every lane's whole parameter tree, leaves `[B, ...]` (B copies of the kernels:
        for tests and inspection, not for acting)."""

        def one(lanes, update):
            params = join_partial_trees(self.shared, lanes)
            kernels = lstm_kernels(encoder_lstm_params(params))._replace(update=update)
            return with_encoder_lstm_kernels(params, kernels)

        return jax.vmap(one, in_axes=(0, 0))(self.lanes, self.lstm_update)


def _per_lane(tree):
    return jax.tree.map(lambda x: x[:, None], tree)  # [B, ...] -> [B, 1, ...]


def _unlane(tree):
    return jax.tree.map(lambda x: x[:, 0], tree)  # [B, 1, ...] -> [B, ...]


class Adaptation(NamedTuple):
    """What the maml base's inner loop gives a window it acts under adapted parameters
    (`adaptive_act`; `foresit_jax.rollout.act_window` reads it); every field may be None.

    alive: `[B]` bool, with `whole_episodes`, which lanes' counted episode is still running
      at the window's start (None: all; a window that continues an earlier one of the same
      whole-episode rollout passes what that one left);
    lstm_update: a low-rank change of the LSTM's kernels (the lanes' adapted kernels);
    gate_offsets: `[num_steps, B, 4H]` added to each step's gate pre-activations (zeros
      whose gradient is the pre-activations')."""

    alive: Optional[chex.Array] = None
    lstm_update: Optional[LowRankUpdate] = None
    gate_offsets: Optional[chex.Array] = None


@dataclasses.dataclass(frozen=True)
class InnerLoop:
    """SAVN's inner loop as `adaptive_act` runs it (the maml base's settings, from the
    Config; Python values, static in the traced program)."""

    segment: int  # steps per inner update (SAVN: 6)
    updates: int  # at most this many inner updates per episode (SAVN: 4)
    lr: float  # the inner SGD's step size
    first_order: bool  # drop the meta-gradient through the inner updates

    @classmethod
    def of(cls, config) -> "InnerLoop":
        return cls(config.maml_segment, config.maml_inner_updates, config.maml_inner_lr, config.maml_first_order)


def adaptive_act(
    nets, acting, env, actor, key: chex.PRNGKey, num_steps: int, options, act_window: Callable
) -> tuple[Any, Any, Any, list[AdaptedParams]]:
    """One whole episode per lane (from `actor`, every lane at an episode start) with
    SAVN's inner loop (`InnerLoop.of(nets.config)`), acting as `acting` (`AgentParams`:
    theta_0, w, the noise variance, `[]` or `[B]`, never None: `rollout.act` sets Eq. 7's)
    in `env` (`BoundEnv`) with `options` (`ActOptions`: greedy, record_inputs; whole
    episodes): each segment is one `act_window` (that of
    `foresit_jax.rollout`, passed in: acting imports this module) under the lane's theta_i
    (`rollout.Adaptation`), its L_phi and the encoder's inputs read through `nets.model`.
    Returns (actor after the window, Trajectory `[num_steps, B]`, its WindowEnd, the
    parameters each lane used: `AdaptedParams`, theta_0 first, then theta_i after each
    update slot (unchanged in lanes whose episode had ended))."""
    loop = InnerLoop.of(nets.config)
    num_lanes = actor.episode_step.shape[0]
    variance = jnp.broadcast_to(jnp.asarray(acting.noise_variance, jnp.float32), (num_lanes,))[:, None]  # [B, 1]
    shared, lanes = split_encoder_lstm_kernels(acting.params)
    lanes = lane_copies(lanes, num_lanes)
    lane_actor = _per_lane(actor)
    alive = jnp.ones((num_lanes, 1), bool)

    def window(lanes, update, lane_actor, key, variance, alive, steps, record, gate_offsets=None):  # one lane
        lane_acting = acting._replace(params=join_partial_trees(shared, lanes), noise_variance=variance)
        lane_options = options._replace(whole_episodes=True, record_inputs=record)
        return act_window(nets, lane_acting, env, lane_actor, key, steps, lane_options,
                          Adaptation(alive, update, gate_offsets))  # fmt: skip

    def segment(lanes, update, lane_actor, key, variance, alive):  # one lane
        def run(lanes, gate_offsets):
            next_actor, traj, end = window(lanes, update, lane_actor, key, variance, alive, loop.segment, True,
                                          gate_offsets)  # fmt: skip
            return traj, (next_actor, end)

        grads, rows, traj, (next_actor, end) = segment_update(nets, loop, shared, lanes, lane_actor.lstm[1], run)
        still_alive = traj.valid[-1] & ~(traj.terminated[-1] | traj.truncated[-1])  # [1] the episode runs on (alive next)
        rows = rows._replace(deltas=jnp.where(still_alive[0], rows.deltas, 0.0))
        update = rows if update is None else update.concat(rows)
        if not options.record_inputs:
            traj = traj._replace(inputs=None)
        return inner_step(lanes, grads, loop.lr, still_alive[0]), update, next_actor, (traj, end), still_alive

    update = None
    thetas, segments, done_steps = [AdaptedParams(shared, lanes, update)], [], 0
    slots = update_steps(num_steps, loop.segment, loop.updates)
    keys = jax.random.split(key, len(slots) + 1)
    for k in keys[:-1]:
        lanes, update, lane_actor, recorded, alive = jax.vmap(segment)(
            lanes, update, lane_actor, jax.random.split(k, num_lanes), variance, alive
        )
        thetas.append(AdaptedParams(shared, lanes, update))
        segments.append(recorded)
        done_steps += loop.segment
    if num_steps > done_steps:
        steps = num_steps - done_steps
        rest = lambda *a: window(*a, steps, options.record_inputs)  # noqa: E731
        lane_actor, traj, end = jax.vmap(rest)(lanes, update, lane_actor, jax.random.split(keys[-1], num_lanes), variance,
                                               alive)  # fmt: skip
        segments.append((traj, end))
    traj, end = _joined(segments)  # (before the actor: the order of the lowered program's ops)
    return _unlane(lane_actor), traj, end, thetas


def segment_update(nets, loop: InnerLoop, shared, lanes, h_before: chex.Array, run: Callable):
    """One lane's inner step after a segment: (the gradient of L_phi with respect to the
    lane's adapted parameters but the LSTM kernels, those kernels' step as factors
    (`LowRankUpdate`, see "Adapted kernels"), `run`'s segment and aux), with the meta-gradient through
    them unless `loop.first_order`.

    run: `(lanes, gate_offsets [segment, 1, 4H]) -> (segment, aux)` plays the segment
    under theta_i = `shared` + `lanes` with the offsets added to its gate pre-activations;
    `segment` has `states` `[segment, 1, H]`, `logits` and the encoder's `inputs` (a
    `Trajectory` recorded with inputs): `adaptive_act` runs it in the environment, the
    step-by-step policy (`foresit_jax.rollout.policy`) on the segment's recorded
    observations. h_before: `[1, H]` the LSTM output entering the segment."""

    def loss(lanes, gate_offsets):
        segment, aux = run(lanes, gate_offsets)
        inputs = interaction_inputs(segment.states[:, 0], segment.logits[:, 0])  # [segment, H + A]
        loss = nets.model.apply(join_partial_trees(shared, lanes), inputs, method="interaction_loss")
        return loss, (segment, aux)

    kernel_dtype = jax.tree.leaves(shared)[0].dtype
    zeros = jnp.zeros((loop.segment, 1, 4 * h_before.shape[-1]), kernel_dtype)  # [segment, 1, 4H]
    (_, (segment, aux)), (grads, gate_grads) = jax.value_and_grad(loss, (0, 1), has_aux=True)(lanes, zeros)
    rows = _kernel_update(nets, loop, join_partial_trees(shared, lanes), h_before, segment, gate_grads)
    if loop.first_order:
        grads, rows = jax.lax.stop_gradient((grads, rows))
    return grads, rows, segment, aux


def _kernel_update(nets, loop: InnerLoop, params, h_before, traj, gate_grads) -> LowRankUpdate:
    """The LSTM kernels' inner step of one lane's segment, as factors (module doc, "Adapted
    kernels"): the gradients sum_t x_t^T delta_t and sum_t h_{t-1}^T delta_t, kept as the
    segment's inputs x_t `[segment, F]` (under `params`, the lane's theta_i), carries
    h_{t-1} `[segment, H]` (`h_before` `[1, H]` first) and -lr delta_t `[segment, 4H]`
    (`gate_grads`: d L_phi / d gates)."""
    seen = traj.inputs
    return LowRankUpdate(
        inputs=nets.model.apply(params, seen.obs, seen.prev_action_probs, seen.encoder_imagined,
                                method="encoder_features")[:, 0],
        hiddens=jnp.concatenate([h_before, traj.states[:-1, 0]]),
        deltas=-loop.lr * gate_grads[:, 0],
    )


def _joined(segments):
    """The lanes' segments, (Trajectory, WindowEnd) each with leaves `[B, steps, 1, ...]`
    (`[B, 1, ...]`), as one Trajectory `[T, B, ...]` and the last segment's WindowEnd `[B, ...]`."""
    per_step = jax.tree.map(lambda *xs: jnp.concatenate(xs, axis=1), *[traj for traj, _ in segments])  # [B, T, 1, ...]
    per_step = jax.tree.map(lambda x: jnp.swapaxes(x[:, :, 0], 0, 1), per_step)  # [T, B, ...]
    return per_step, jax.tree.map(lambda x: x[:, 0], segments[-1][1])
