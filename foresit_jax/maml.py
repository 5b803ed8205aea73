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
* Test time runs the same inner loop (`Agent.rollout` calls the same `adaptive_act`), with
  no meta-step; actions are sampled (SAVN's validation samples too).

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
* Lanes are SAVN's workers: each lane adapts its own copy of the parameters (they are
  vmapped over lanes), and one meta-update takes the A3C loss's mean over all lanes'
  valid steps (the synchronous stand-in for SAVN's asynchronous one-episode gradients;
  a longer episode weighs more, as in the other methods' whole-episode updates).
"""

from __future__ import annotations

from typing import Any, Callable

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp
from flax import traverse_util

from foresit_jax import distributions, imagination

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


def _per_lane(tree):
    return jax.tree.map(lambda x: x[:, None], tree)  # [B, ...] -> [B, 1, ...]


def _unlane(tree):
    return jax.tree.map(lambda x: x[:, 0], tree)  # [B, 1, ...] -> [B, ...]


def adaptive_act(
    agent, params, w_params, env, env_params, actor, key: chex.PRNGKey, num_steps: int, *,
    greedy: bool = False, noise_variance: chex.Array | None = None, record_inputs: bool = True,
) -> tuple[Any, Any, Any]:  # fmt: skip
    """One whole episode per lane (from `actor`, every lane at an episode start) with
    SAVN's inner loop. Returns (actor after the window, Trajectory `[num_steps, B]`,
    the parameters each lane used: a list of per-lane trees `[B, ...]`, theta_0 first,
    then theta_i after each update slot (unchanged in lanes whose episode had ended))."""
    cfg = agent.config
    num_lanes = actor.episode_step.shape[0]
    if noise_variance is None:  # Eq. 7 from each lane's tracker (it changes only when the episode ends)
        rho = jax.vmap(imagination.success_rate)(actor.tracker)
        noise_variance = imagination.noise_variance(rho, cfg.sigma2_max)
    variance = jnp.broadcast_to(jnp.asarray(noise_variance, jnp.float32), (num_lanes,))[:, None]  # [B, 1]
    theta = jax.tree.map(lambda x: jnp.broadcast_to(x, (num_lanes,) + x.shape), params)
    lane_actor = _per_lane(actor)
    alive = jnp.ones((num_lanes, 1), bool)

    def window(theta, lane_actor, key, variance, alive, steps):  # one lane, its own parameters
        return agent.act_window(
            theta, w_params, env, env_params, lane_actor, key, steps, greedy=greedy, whole_episodes=True,
            noise_variance=variance, record_inputs=record_inputs, alive=alive,
        )  # fmt: skip

    def segment(theta, lane_actor, key, variance, alive):
        def loss(th):
            next_actor, traj = window(th, lane_actor, key, variance, alive, cfg.maml_segment)
            inputs = interaction_inputs(traj.states[:, 0], traj.logits[:, 0])  # [segment, H + A]
            return agent.interaction_loss(th, inputs), (next_actor, traj)

        (_, (next_actor, traj)), grads = jax.value_and_grad(loss, has_aux=True)(theta)
        if cfg.maml_first_order:
            grads = jax.lax.stop_gradient(grads)
        going = traj.valid[-1] & ~(traj.terminated[-1] | traj.truncated[-1])  # [1] the episode runs on
        return inner_step(theta, grads, cfg.maml_inner_lr, going[0]), next_actor, traj, going

    thetas, trajs, done_steps = [theta], [], 0
    slots = update_steps(num_steps, cfg.maml_segment, cfg.maml_inner_updates)
    keys = jax.random.split(key, len(slots) + 1)
    for k in keys[:-1]:
        theta, lane_actor, traj, alive = jax.vmap(segment)(theta, lane_actor, jax.random.split(k, num_lanes), variance, alive)
        thetas.append(theta)
        trajs.append(traj)
        done_steps += cfg.maml_segment
    if num_steps > done_steps:
        rest = lambda *a: window(*a, num_steps - done_steps)  # noqa: E731
        lane_actor, traj = jax.vmap(rest)(theta, lane_actor, jax.random.split(keys[-1], num_lanes), variance, alive)
        trajs.append(traj)
    last = trajs[-1]
    per_step = [t._replace(next_state=None, next_episode_step=None) for t in trajs]
    per_step = jax.tree.map(lambda *xs: jnp.concatenate(xs, axis=1), *per_step)  # leaves [B, T, 1, ...]
    per_step = jax.tree.map(lambda x: jnp.swapaxes(x[:, :, 0], 0, 1), per_step)  # [T, B, ...]
    traj = per_step._replace(next_state=last.next_state[:, 0], next_episode_step=last.next_episode_step[:, 0])
    return _unlane(lane_actor), traj, thetas
