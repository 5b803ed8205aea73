"""Return/advantage estimation and the losses of the paper (Eq. 5, Eq. 8-9).

Conventions (as rlax, but time-major and batch-agnostic): every per-step array is
`[T, ...]` with time first; any trailing batch shape (`[T]`, `[T, B]`) works because the
recursions `lax.scan` over the leading axis only. `r_t` is the reward received after
acting at step t, `v_t` the value estimate of the state at step t, `discount_t` the
discount applied to whatever follows step t (0 where the episode ended there).

Episode ends inside a window. One training update runs every env lane for a window of
`T` steps: with packed windows (the default) episodes follow one another and every step is
valid; with whole-episode windows (`Config.rollout='episodes'`, and evaluation) each lane
plays one episode padded to `T` steps, and `valid_t` is 1 for the steps of that episode
(including its last one) and 0 for the padding after it. Three rules, in
`episode_discounts`:
* `terminated_t` (the agent chose Done): nothing follows, no bootstrap.
* `truncated_t` (time limit): also no bootstrap, as in SAVN (its `a3c_loss` sets R = 0
  whenever the episode is over, time limit included); docs/design.md, one update's step 4:
  "Done and the time limit bootstrap nothing".
* padding: a padding step neither contributes (outputs are zeroed) nor is bootstrapped
  from (the step before it gets discount 0 even without a done flag).

Only when the last step of the rollout is valid and the episode is still running does
`bootstrap_value` (the value of the state after the rollout) enter.
"""

from __future__ import annotations

from typing import Mapping

import chex
import jax
import jax.numpy as jnp

from foresit_jax import distributions


def episode_discounts(
    terminated_t: chex.Array,
    truncated_t: chex.Array,
    valid_t: chex.Array,
    gamma: float,
) -> chex.Array:
    """Per-step discounts `[T, ...]` for a padded rollout.

    discount_t = gamma * valid_t * (1 - (terminated_t | truncated_t)) * valid_{t+1},
    with valid_T := 1 (a running episode at the rollout's end is bootstrapped).
    """
    chex.assert_equal_shape([terminated_t, truncated_t, valid_t])
    ended_t = jnp.logical_or(terminated_t.astype(bool), truncated_t.astype(bool))
    valid = valid_t.astype(bool)
    valid_tp1 = jnp.concatenate([valid[1:], jnp.ones_like(valid[:1])], axis=0)
    keep = valid & ~ended_t & valid_tp1
    return gamma * keep.astype(jnp.float32)


def discounted_returns(
    r_t: chex.Array, discount_t: chex.Array, bootstrap_value: chex.Array
) -> chex.Array:
    """Discounted returns R_t = r_t + discount_t * R_{t+1}, R_T = bootstrap_value.

    Shapes: `r_t`, `discount_t` `[T, ...]`; `bootstrap_value` `[...]`. Returns `[T, ...]`.
    This is SAVN's value target R (Monte Carlo with bootstrap); it equals
    GAE(lambda=1) + v_t.
    """
    chex.assert_equal_shape([r_t, discount_t])
    chex.assert_equal_shape([r_t[0], bootstrap_value])

    def step(acc, inputs):
        r, discount = inputs
        acc = r + discount * acc
        return acc, acc

    _, returns = jax.lax.scan(step, bootstrap_value, (r_t, discount_t), reverse=True)
    return returns


def generalized_advantage_estimation(
    r_t: chex.Array,
    v_t: chex.Array,
    discount_t: chex.Array,
    bootstrap_value: chex.Array,
    lambda_: float,
) -> chex.Array:
    """GAE: A_t = delta_t + discount_t * lambda * A_{t+1}, A_T = 0, where
    delta_t = r_t + discount_t * v_{t+1} - v_t and v_T = bootstrap_value.

    Shapes: `r_t`, `v_t`, `discount_t` `[T, ...]`; `bootstrap_value` `[...]`.
    SAVN's `tau` is this `lambda_` (1.0 there).
    """
    chex.assert_equal_shape([r_t, v_t, discount_t])
    chex.assert_equal_shape([r_t[0], bootstrap_value])
    v_tp1 = jnp.concatenate([v_t[1:], bootstrap_value[None]], axis=0)  # [T, ...]
    delta_t = r_t + discount_t * v_tp1 - v_t  # [T, ...]

    def step(acc, inputs):
        delta, discount = inputs
        acc = delta + discount * lambda_ * acc
        return acc, acc

    _, advantages = jax.lax.scan(
        step, jnp.zeros_like(bootstrap_value), (delta_t, discount_t), reverse=True
    )
    return advantages


def advantages_and_returns(
    r_t: chex.Array,
    v_t: chex.Array,
    terminated_t: chex.Array,
    truncated_t: chex.Array,
    valid_t: chex.Array,
    bootstrap_value: chex.Array,
    gamma: float,
    lambda_: float,
) -> tuple[chex.Array, chex.Array]:
    """(advantage_t, return_t), both `[T, ...]` and zero on padding steps.

    The two A3C targets from one padded rollout: GAE(lambda) advantages for the policy
    and discounted returns for the value (Eq. 8-9). Inputs are treated as constants
    (`stop_gradient`), so `v_t` may come straight from the differentiated forward pass.
    """
    r_t, v_t, bootstrap_value = jax.lax.stop_gradient((r_t, v_t, bootstrap_value))
    valid = valid_t.astype(jnp.float32)
    discount_t = episode_discounts(terminated_t, truncated_t, valid_t, gamma)
    r_t = r_t * valid  # padding rewards never enter a recursion
    v_t = v_t * valid
    advantage_t = generalized_advantage_estimation(
        r_t, v_t, discount_t, bootstrap_value, lambda_
    )
    return_t = discounted_returns(r_t, discount_t, bootstrap_value)
    return advantage_t * valid, return_t * valid


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


def masked_mean(x: chex.Array, mask: chex.Array) -> chex.Array:
    """Mean of `x` over entries where `mask` is 1 (0.0 when the mask is empty)."""
    chex.assert_equal_shape([x, mask])
    mask = mask.astype(x.dtype)
    return jnp.sum(x * mask) / jnp.maximum(jnp.sum(mask), 1.0)


def masked_variance(x: chex.Array, mask: chex.Array) -> chex.Array:
    """Population variance of `x` over the entries where `mask` is 1 (0.0 when empty)."""
    mean = masked_mean(x, mask)
    return masked_mean((x - mean) ** 2, mask)


def explained_variance(v_t: chex.Array, return_t: chex.Array, mask: chex.Array) -> chex.Array:
    """1 - Var(R - v) / Var(R) over the masked entries: how much of the returns' spread
    the value baseline explains (1: all, 0: no better than their mean, < 0: worse);
    0.0 where the returns do not vary."""
    var_return = masked_variance(return_t, mask)
    ratio = masked_variance(return_t - v_t, mask) / jnp.maximum(var_return, 1e-8)
    return jnp.where(var_return > 1e-8, 1.0 - ratio, 0.0)


def a3c_loss(
    logits_t: chex.Array,
    a_t: chex.Array,
    v_t: chex.Array,
    advantage_t: chex.Array,
    return_t: chex.Array,
    valid_t: chex.Array,
    entropy_coef: float = 0.01,
    value_coef: float = 0.5,
) -> tuple[chex.Array, Mapping[str, chex.Array]]:
    """The A3C objective of Eq. 8-9 (Eq. 1-2 with V(s*_t) for ForeSIT).

    Args:
      logits_t: `[T, ..., A]` policy logits (differentiated).
      a_t: `[T, ...]` int actions taken.
      v_t: `[T, ...]` value estimates V(s*_t) (or V(s_t)), differentiated.
      advantage_t, return_t: `[T, ...]` targets from `advantages_and_returns`
        (stop-gradient is applied here too).
      valid_t: `[T, ...]` 1 on real steps, 0 on padding.

    Per step: policy term -log pi(a_t) * A_t - entropy_coef * H(pi_t); value term
    0.5 * (v_t - R_t)**2. Each is a masked mean over valid steps (SAVN sums over one
    episode; a mean keeps the scale independent of T and of the number of lanes).
    total = policy + value_coef * value.

    Returns (total_loss scalar, metrics dict of scalars).
    """
    chex.assert_equal_shape([a_t, v_t, advantage_t, return_t, valid_t])
    chex.assert_equal_shape_prefix([logits_t, a_t], a_t.ndim)
    advantage_t, return_t = jax.lax.stop_gradient((advantage_t, return_t))
    logp_t = distributions.log_prob(logits_t, a_t)  # [T, ...]
    entropy_t = distributions.entropy(logits_t)  # [T, ...]

    policy_gradient_loss = masked_mean(-logp_t * advantage_t, valid_t)
    entropy = masked_mean(entropy_t, valid_t)
    policy_loss = policy_gradient_loss - entropy_coef * entropy
    value_loss = masked_mean(0.5 * (v_t - return_t) ** 2, valid_t)
    total_loss = policy_loss + value_coef * value_loss

    metrics = {
        "losses/total_loss": total_loss,
        "losses/policy_loss": policy_loss,
        "losses/policy_gradient_loss": policy_gradient_loss,
        "losses/value_loss": value_loss,
        "losses/entropy": entropy,
        "losses/advantage_mean": masked_mean(advantage_t, valid_t),
        "losses/advantage_std": jnp.sqrt(masked_variance(advantage_t, valid_t)),
        "losses/explained_variance": explained_variance(jax.lax.stop_gradient(v_t), return_t, valid_t),
        "losses/value_mean": masked_mean(jax.lax.stop_gradient(v_t), valid_t),
        "losses/return_mean": masked_mean(return_t, valid_t),
        "losses/num_valid_steps": jnp.sum(valid_t.astype(jnp.float32)),
    }
    return total_loss, metrics
