"""SAVN's self-adaptive learner (the `maml` base): a learned interaction loss L_phi, inner
SGD steps on it inside every episode, and an exact second-order meta-gradient.

Read from allenai/savn (models/savn.py, models/tcn.py, runners/savn_train.py,
runners/train_util.py, runners/savn_val.py, agents/agent.py) and kept as it is there:

* After every step the agent records [h_t : pi_t] (the LSTM output and the action
  probabilities of that step, H + A values; nothing detached). L_phi
  (`foresit_jax.learned_loss.LearnedLoss`, a module of the network) reads the last
  `segment` (6) of them.
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
* Test time runs the same inner loop (the Evaluator's `rollout.rollout` calls `act`, as the
  Trainer does), with no meta-step; actions are sampled (SAVN's validation samples too).

This module is the maml base's acting: `act`, the window the Trainer and the Evaluator
choose for this base (it calls `rollout.act_window` once per segment), and `policy` with
`policy_carry`, the same agent step by step (as `foresit_jax.policy` is the a3c base's).

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
import functools
from typing import Any, Callable, NamedTuple, Optional

import chex
import jax
import jax.numpy as jnp
from flax import traverse_util

from foresit_jax import distributions, imagination, learned_loss, rollout
from foresit_jax.lstm import (
    LowRankUpdate,
    encoder_lstm_params,
    join_partial_trees,
    lane_copies,
    lstm_kernels,
    split_encoder_lstm_kernels,
    with_encoder_lstm_kernels,
)
from foresit_jax.networks import ActorCritic, Networks
from foresit_jax.policy import StepPolicy, policy_step, reset, with_noise
from foresit_jax.rollout import (
    ActOptions,
    ActorState,
    Adaptation,
    AgentCarry,
    AgentParams,
    BoundEnv,
    StepInputs,
    Trajectory,
    WindowEnd,
    advance,
    agent_carry,
    agent_step,
)


def interaction_inputs(states: chex.Array, logits: chex.Array) -> chex.Array:
    """[h_t : pi_t] per step, `[..., H + A]` (what L_phi reads)."""
    return jnp.concatenate([states, distributions.probs(logits)], axis=-1)


def adapts(path: tuple[str, ...]) -> bool:
    """Whether the inner loop adapts the parameter at `path` (everything but phi)."""
    return learned_loss.SCOPE not in path


def inner_step(params, grads, lr: float, apply: chex.Array = True):
    """theta - lr * grad on every adapted leaf (phi is passed through); where `apply` is
    False the parameters are returned unchanged."""
    flat_p = traverse_util.flatten_dict(params)
    flat_g = traverse_util.flatten_dict(grads)
    out = {path: jnp.where(apply, p - lr * flat_g[path], p) if adapts(path) else p for path, p in flat_p.items()}
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


def act(
    nets: Networks,
    acting: AgentParams,
    env: BoundEnv,
    actor: ActorState,
    key: chex.PRNGKey,
    num_steps: int,
    options: ActOptions = ActOptions(),
) -> tuple[ActorState, Trajectory, WindowEnd]:
    """The maml base's window, with `rollout.act_window`'s arguments and returns: one whole
    episode per lane under SAVN's inner loop (`adaptive_act`), in training and evaluation.
    The noise variance, unless given, is Eq. 7's from each lane's success tracker (it
    changes only when an episode ends)."""
    if not options.whole_episodes or options.step_keys is not None:
        raise ValueError("the maml base acts in whole episodes (rollout='episodes'), without step_keys")
    if acting.noise_variance is None:
        rho = jax.vmap(imagination.success_rate)(actor.agent.imagination.tracker)
        acting = acting._replace(noise_variance=imagination.noise_variance(rho, nets.config.sigma2_max))
    actor, traj, end, _ = adaptive_act(nets, acting, env, actor, key, num_steps, options)
    return actor, traj, end


def adaptive_act(
    nets: Networks,
    acting: AgentParams,
    env: BoundEnv,
    actor: ActorState,
    key: chex.PRNGKey,
    num_steps: int,
    options: ActOptions,
) -> tuple[ActorState, Trajectory, WindowEnd, list[AdaptedParams]]:
    """One whole episode per lane (from `actor`, every lane at an episode start) with
    SAVN's inner loop (`InnerLoop.of(nets.config)`), acting as `acting` (`AgentParams`:
    theta_0, w, the noise variance, `[]` or `[B]`, never None: `act` sets Eq. 7's) in `env`
    with `options` (greedy, record_inputs; whole episodes): each segment is one
    `rollout.act_window` under the lane's theta_i (`rollout.Adaptation`), its L_phi and the
    encoder's inputs read through `nets.model`. Returns (actor after the window, Trajectory
    `[num_steps, B]`, its WindowEnd, the parameters each lane used: `AdaptedParams`,
    theta_0 first, then theta_i after each update slot (unchanged in lanes whose episode
    had ended))."""
    loop = InnerLoop.of(nets.config)
    num_lanes = actor.agent.episode_step.shape[0]
    variance = jnp.broadcast_to(jnp.asarray(acting.noise_variance, jnp.float32), (num_lanes,))[:, None]  # [B, 1]
    shared, lanes = split_encoder_lstm_kernels(acting.params)
    lanes = lane_copies(lanes, num_lanes)
    lane_actor = _per_lane(actor)
    alive = jnp.ones((num_lanes, 1), bool)

    def window(lanes, update, lane_actor, key, variance, alive, steps, record, gate_offsets=None):  # one lane
        lane_acting = acting._replace(params=join_partial_trees(shared, lanes), noise_variance=variance)
        lane_options = options._replace(whole_episodes=True, record_inputs=record)
        return rollout.act_window(
            nets, lane_acting, env, lane_actor, key, steps, lane_options, Adaptation(alive, update, gate_offsets)
        )

    def segment(lanes, update, lane_actor, key, variance, alive):  # one lane
        def run(lanes, gate_offsets):
            next_actor, traj, end = window(
                lanes, update, lane_actor, key, variance, alive, loop.segment, True, gate_offsets
            )
            return traj, (next_actor, end)

        grads, rows, traj, (next_actor, end) = segment_update(nets, loop, shared, lanes, lane_actor.agent.lstm[1], run)
        still_alive = traj.valid[-1] & ~(
            traj.terminated[-1] | traj.truncated[-1]
        )  # [1] the episode runs on (alive next)
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
        lane_actor, traj, end = jax.vmap(rest)(
            lanes, update, lane_actor, jax.random.split(keys[-1], num_lanes), variance, alive
        )
        segments.append((traj, end))
    traj, end = _joined(segments)  # (before the actor: the order of the lowered program's ops)
    return _unlane(lane_actor), traj, end, thetas


def segment_update(nets: Networks, loop: InnerLoop, shared, lanes, h_before: chex.Array, run: Callable):
    """One lane's inner step after a segment: (the gradient of L_phi with respect to the
    lane's adapted parameters but the LSTM kernels, those kernels' step as factors
    (`LowRankUpdate`, see "Adapted kernels"), `run`'s segment and aux), with the meta-gradient through
    them unless `loop.first_order`.

    run: `(lanes, gate_offsets [segment, 1, 4H]) -> (segment, aux)` plays the segment
    under theta_i = `shared` + `lanes` with the offsets added to its gate pre-activations;
    `segment` has `states` `[segment, 1, H]`, `logits` and the encoder's `inputs` (a
    `Trajectory` recorded with inputs): `adaptive_act` runs it in the environment, the
    step-by-step policy (`policy`) on the segment's recorded
    observations. h_before: `[1, H]` the LSTM output entering the segment."""

    def loss(lanes, gate_offsets):
        segment, aux = run(lanes, gate_offsets)
        inputs = interaction_inputs(segment.states[:, 0], segment.logits[:, 0])  # [segment, H + A]
        loss = nets.model.apply(join_partial_trees(shared, lanes), inputs, method=ActorCritic.interaction_loss)
        return loss, (segment, aux)

    kernel_dtype = jax.tree.leaves(shared)[0].dtype
    zeros = jnp.zeros((loop.segment, 1, 4 * h_before.shape[-1]), kernel_dtype)  # [segment, 1, 4H]
    (_, (segment, aux)), (grads, gate_grads) = jax.value_and_grad(loss, (0, 1), has_aux=True)(lanes, zeros)
    rows = _kernel_update(nets, loop, join_partial_trees(shared, lanes), h_before, segment, gate_grads)
    if loop.first_order:
        grads, rows = jax.lax.stop_gradient((grads, rows))
    return grads, rows, segment, aux


def _kernel_update(nets: Networks, loop: InnerLoop, params, h_before, traj, gate_grads) -> LowRankUpdate:
    """The LSTM kernels' inner step of one lane's segment, as factors (module doc, "Adapted
    kernels"): the gradients sum_t x_t^T delta_t and sum_t h_{t-1}^T delta_t, kept as the
    segment's inputs x_t `[segment, F]` (under `params`, the lane's theta_i), carries
    h_{t-1} `[segment, H]` (`h_before` `[1, H]` first) and -lr delta_t `[segment, 4H]`
    (`gate_grads`: d L_phi / d gates)."""
    seen = traj.inputs
    return LowRankUpdate(
        inputs=nets.model.apply(
            params, seen.obs, seen.prev_action_probs, seen.encoder_imagined, method=ActorCritic.encoder_features
        )[:, 0],
        hiddens=jnp.concatenate([h_before, traj.states[:-1, 0]]),
        deltas=-loop.lr * gate_grads[:, 0],
    )


def _joined(segments):
    """The lanes' segments, (Trajectory, WindowEnd) each with leaves `[B, steps, 1, ...]`
    (`[B, 1, ...]`), as one Trajectory `[T, B, ...]` and the last segment's WindowEnd `[B, ...]`."""
    per_step = jax.tree.map(lambda *xs: jnp.concatenate(xs, axis=1), *[traj for traj, _ in segments])  # [B, T, 1, ...]
    per_step = jax.tree.map(lambda x: jnp.swapaxes(x[:, :, 0], 0, 1), per_step)  # [T, B, ...]
    return per_step, jax.tree.map(lambda x: x[:, 0], segments[-1][1])


# ---------------------------------------------------------------------- the maml base, step by step


class AdaptiveCarry(NamedTuple):
    """What the maml base's `policy` carries, per lane (leaves `[B, ...]`): the policy's
    carry, the lane's adapted parameters theta_i (as `adaptive_act` keeps them: every
    parameter but the LSTM kernels, and the kernels' low-rank change, zero rows beyond the
    updates made so far), and the running segment, which the next inner step learns from."""

    policy: AgentCarry
    lanes: Any  # theta_i but the encoder LSTM's kernels, leaves [B, ...]
    update: LowRankUpdate  # [B, segment * updates, ...] the kernels' change so far
    segment_start: AgentCarry  # the carry that entered the running segment's first step
    seen_obs: Any  # [B, segment, ...] the running segment's observations
    seen_keys: chex.Array  # [B, segment, 2] its steps' keys


def adaptive_keys(loop: InnerLoop, key: chex.PRNGKey, num_steps: int, num_lanes: int) -> tuple[chex.Array, chex.Array]:
    """The keys `adaptive_act` gives a whole-episode rollout, for a step-by-step replay:
    one key per segment (the update slots' and the rest's, `split(key, slots + 1)`), split
    per lane, then per step: (the policy's `[T, B, 2]`, one per lane; the environment's
    `[T, B, 2]`, `split(split(step key, 3)[2], 1)[0]`, each lane stepped alone)."""
    slots = update_steps(num_steps, loop.segment, loop.updates)
    lengths = [loop.segment] * len(slots) + [num_steps - loop.segment * len(slots)]
    keys = jax.random.split(key, len(slots) + 1)
    per_segment = [
        jnp.swapaxes(jax.vmap(lambda k, n=n: jax.random.split(k, n))(jax.random.split(k, num_lanes)), 0, 1)
        for k, n in zip(keys, lengths)
    ]
    policy_keys = jnp.concatenate(per_segment)  # [T, B, 2]
    env_key = lambda k: jax.random.split(jax.random.split(k, 3)[2], 1)[0]  # noqa: E731
    return policy_keys, jax.vmap(jax.vmap(env_key))(policy_keys)


def policy_carry(nets: Networks, num_lanes: int, acting: Optional[AgentParams] = None, obs=None) -> AdaptiveCarry:
    """The maml base's carry before any step: `foresit_jax.policy`'s zeros, each lane's
    theta_0 and an empty segment. It needs `acting` (its theta_0) and `obs`, one unbatched
    observation of the environment or its shapes (`jax.eval_shape`), to shape the segment."""
    if acting is None or obs is None:
        raise ValueError(
            f"method {nets.method.name!r}: the maml base's carry holds each lane's adapted parameters and "
            "its running segment; give maml.policy_carry(nets, num_lanes, acting=AgentParams(...), "
            "obs=one observation) (experiments.load's initial_carry does)"
        )
    loop, hidden = InnerLoop.of(nets.config), nets.config.hidden_size
    carry = agent_carry(nets, num_lanes)
    _, lanes = split_encoder_lstm_kernels(acting.params)
    kernels = nets.lstm_kernels(acting.params)
    rows, dtype = loop.segment * loop.updates, kernels.input_kernel.dtype
    update = LowRankUpdate(
        jnp.zeros((num_lanes, rows, kernels.input_kernel.shape[0]), dtype),
        jnp.zeros((num_lanes, rows, hidden), dtype),
        jnp.zeros((num_lanes, rows, 4 * hidden), dtype),
    )
    return AdaptiveCarry(
        policy=carry,
        lanes=lane_copies(lanes, num_lanes),
        update=update,
        segment_start=carry,
        seen_obs=jax.tree.map(lambda x: jnp.zeros((num_lanes, loop.segment) + tuple(x.shape), x.dtype), obs),
        seen_keys=jnp.zeros((num_lanes, loop.segment, 2), jnp.uint32),
    )


class _Replayed(NamedTuple):
    """A segment replayed on its recorded observations (what `segment_update` reads)."""

    states: chex.Array  # [segment, 1, H]
    logits: chex.Array  # [segment, 1, A]
    inputs: StepInputs  # [segment, 1, ...]


def _replayed_segment(
    nets: Networks, acting: AgentParams, kernels, start: AgentCarry, seen_obs, seen_keys, gate_offsets
) -> _Replayed:
    """`act_window`'s agent half over one lane's recorded segment (`[1, ...]` leaves; obs
    `[segment, 1, ...]`, keys `[segment, 2]`), the episode running throughout: the same
    states and logits, as functions of `acting.params`, without the environment."""

    def step(agent, xs):
        obs, key, gate_offset = xs
        k_imag = jax.random.split(key, 3)[0]
        out = agent_step(nets, acting, kernels, agent, obs, k_imag, gate_offset)
        policy_input = out.imagined if nets.imagination_in_head else None
        seen = StepInputs(obs, agent.prev_probs, policy_input, out.encoder_imagined)
        return advance(nets, agent, out), _Replayed(out.state, out.logits, seen)

    _, out = jax.lax.scan(step, start, (seen_obs, seen_keys, gate_offsets))
    return out


def _where_lanes(mask: chex.Array, new, old):
    """`new` where `mask` `[B]` is true, else `old` (trees of leaves `[B, ...]`)."""
    return jax.tree.map(lambda n, o: jnp.where(mask.reshape((-1,) + (1,) * (o.ndim - 1)), n, o), new, old)


def policy(nets: Networks, greedy: bool = False) -> StepPolicy:
    """The maml base step by step, as `foresit_jax.policy.policy` (same arguments; its
    carry is `policy_carry`'s): each lane adapts its own parameters after steps 6, 12, 18
    and 24 of its episode, by `segment_update` on the segment it has just played (replayed
    from the observations the carry kept), and starts every episode from theta_0. Each
    lane acts alone, as `adaptive_act`'s lanes do, with its own key: `step_keys`
    (`adaptive_keys`) gives one `[B, 2]` per step, and the replay is exact."""
    loop = InnerLoop.of(nets.config)
    lane = lambda tree, axis=0: jax.tree.map(lambda x: jnp.expand_dims(x, axis), tree)  # noqa: E731  a lane of 1

    def act(acting: AgentParams, carry: AdaptiveCarry, obs, first: chex.Array, keys: chex.Array):
        num_lanes = first.shape[0]
        acting = with_noise(acting, num_lanes)
        shared, theta_0 = split_encoder_lstm_kernels(acting.params)
        # A new episode starts from theta_0.
        lanes = _where_lanes(first, lane_copies(theta_0, num_lanes), carry.lanes)
        update = _where_lanes(first, jax.tree.map(jnp.zeros_like, carry.update), carry.update)
        step_carry = reset(carry.policy, first)
        episode_step = step_carry.episode_step
        slot = episode_step // loop.segment  # the updates made before this step
        adapting = (episode_step > 0) & (episode_step % loop.segment == 0) & (slot <= loop.updates)

        def lane_params(lanes, update):
            params = join_partial_trees(shared, lanes)
            return params, nets.lstm_kernels(params, update)

        def lane_update(lanes, update, start, seen_obs, seen_keys, variance, slot):  # one lane: theta_i -> theta_i+1
            def run(lanes, gate_offsets):
                params, kernels = lane_params(lanes, update)
                lane_acting = acting._replace(params=params, noise_variance=variance[None])
                segment = _replayed_segment(
                    nets, lane_acting, kernels, lane(start), lane(seen_obs, 1), seen_keys, gate_offsets
                )
                return segment, None

            grads, rows, _, _ = segment_update(nets, loop, shared, lanes, lane(start.lstm[1]), run)
            at = (slot - 1) * loop.segment
            update = jax.tree.map(lambda u, r: jax.lax.dynamic_update_slice_in_dim(u, r, at, 0), update, rows)
            return inner_step(lanes, grads, loop.lr), update

        def adapted():
            new = jax.vmap(lane_update)(
                lanes, update, carry.segment_start, carry.seen_obs, carry.seen_keys, acting.noise_variance, slot
            )
            return _where_lanes(adapting, new, (lanes, update))

        lanes, update = jax.lax.cond(jnp.any(adapting), adapted, lambda: (lanes, update))

        def lane_step(lanes, update, step_carry, obs, key, variance):  # one lane, as adaptive_act's act alone
            params, kernels = lane_params(lanes, update)
            lane_acting = acting._replace(params=params, noise_variance=variance[None])
            action, next_carry = policy_step(nets, lane_acting, kernels, lane(step_carry), lane(obs), key, greedy)
            return action[0], jax.tree.map(lambda x: x[0], next_carry)

        action, next_carry = jax.vmap(lane_step)(lanes, update, step_carry, obs, keys, acting.noise_variance)
        at, rows = episode_step % loop.segment, jnp.arange(num_lanes)  # the step's place in its segment
        seen_obs = jax.tree.map(lambda buf, o: buf.at[rows, at].set(o), carry.seen_obs, obs)
        seen_keys = carry.seen_keys.at[rows, at].set(keys)
        segment_start = _where_lanes(at == 0, step_carry, carry.segment_start)
        return action, AdaptiveCarry(next_carry, lanes, update, segment_start, seen_obs, seen_keys)

    return StepPolicy(act, functools.partial(adaptive_keys, loop))
