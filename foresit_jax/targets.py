"""Imagination as a training target: a linear head on the recurrent state s_t learns to
predict a target y_t at every valid step of a window, with weight lambda beside the
actor-critic loss (`Config.aux_target`, `Config.aux_weight`); nothing of it acts.

    L = L_A3C + lambda * mean over labelled steps of loss(W s_t + b, stop_gradient(y_t))

The head's parameters are a tree of their own (`RunnerState.targets`, beside f_w's), with
an optimiser of their own (the base's: gradient clipping and Adam at the base's rate), so
the programs that act and evaluate (`foresit_jax.evaluate`, `foresit_jax.policy`) are the
base's, and nothing privileged is read at test time. The target reaches the agent only
through the gradient its loss sends into the encoder, through s_t.

The targets (`AUX_TARGETS`), each a documented option:

* ``compass`` (a privileged label in training): the bearing and distance of the nearest
  target cell from the step's pose, ``(cos b, sin b, d / G)``, as the ``compass`` cue
  computes them (`envs.wrappers.CueWrapper`, which wraps the training environment alone);
  squared error, summed over the three components.
* ``goal_view`` (a privileged label in training): the agent's own latent of the episode's
  goal view (the `oracle` imagination's i_tau before noise: the encoder and one LSTM step
  from a fresh carry on the goal view, `envs.wrappers.GoalViewWrapper`), computed in the
  loss from the parameters of this update (without gradient) at every step: the label
  follows the encoder as it learns, where a latent computed at the episode's start in
  acting would be that of the parameters of an earlier update for an episode that began
  in an earlier window. Smooth-L1 (the paper's f_w loss, `imagination.smooth_l1`).
* ``success`` (not privileged): the agent's own state at the step where its episode
  succeeded, for the earlier steps of that episode that share the success step's window
  (the success step itself excluded; steps whose episode failed, or ends after the
  window, are not labelled). Smooth-L1. `labelled_fraction` is logged every update.

Each is a pure function of a window (`Trajectory`-shaped arrays `[T, B, ...]`); the
Trainer (`foresit_jax.train`) calls `window_loss` from its replay loss.
"""

from __future__ import annotations

from typing import Callable, NamedTuple, Optional

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp

from envs.wrappers import CUES, CueWrapper, GoalViewWrapper
from foresit_jax.config import AUX_TARGETS, Config
from foresit_jax.imagination import smooth_l1
from foresit_jax.layers import Dense

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


class Labels(NamedTuple):
    """What the head learns on one window: `y` `[T, B, width]` (without gradient) and
    `mask` `[T, B]` bool, the steps labelled."""

    y: chex.Array
    mask: chex.Array


def width(config: Config) -> int:
    """The target's width: the compass's 3 floats, or a latent's `hidden_size`."""
    return CUES["compass"] if config.aux_target == "compass" else config.hidden_size


def head(config: Config) -> TargetHead:
    return TargetHead(width(config))


def label_env(config: Config, env):
    """The training environment wrapped to carry the target's labels (`obs["cue"]` for
    ``compass``, `obs["goal_view"]` for ``goal_view``); `env` itself otherwise. Training
    alone acts in it: evaluation builds its own environment, the base's."""
    if config.aux_target == "compass":
        return CueWrapper(env, "compass")
    if config.aux_target == "goal_view":
        return GoalViewWrapper(env)
    return env


def success_labels(states, terminated, truncated, success, valid) -> Labels:
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
    return Labels(jax.lax.stop_gradient(y), mask)


def labels(config: Config, obs: dict, states, traj, goal_latent: Optional[Callable] = None) -> Labels:
    """The labels of one window for `config.aux_target`. obs: the window's recorded
    observations (leaves `[T, B, ...]`, from the label environment); states: s_t `[T, B, H]`;
    traj: the window's `Trajectory` (terminated, truncated, success, valid);
    goal_latent: `obs -> [N, H]`, the goal view's latent under this update's parameters
    (``goal_view`` only)."""
    target, valid = config.aux_target, traj.valid
    if target == "compass":
        return Labels(obs["cue"], valid)
    if target == "goal_view":
        lead = valid.shape
        flat = jax.tree.map(lambda x: jnp.reshape(x, (-1, *x.shape[len(lead) :])), obs)
        latent = jnp.reshape(goal_latent(flat), (*lead, -1))
        return Labels(jax.lax.stop_gradient(latent), valid)
    if target == "success":
        return success_labels(states, traj.terminated, traj.truncated, traj.success, valid)
    raise ValueError(f"aux_target must be one of {AUX_TARGETS[1:]}, got {target!r}")


def per_step_loss(target: str, prediction: chex.Array, y: chex.Array) -> chex.Array:
    """`[T, B]`: the compass's squared error summed over its components, a latent's smooth-L1
    (averaged over its dimensions, as f_w's loss)."""
    y = jax.lax.stop_gradient(y)
    if target == "compass":
        return jnp.sum((prediction - y) ** 2, axis=-1)
    return smooth_l1(prediction, y)


def window_loss(config: Config, head_params, states: chex.Array, labels: Labels) -> tuple[chex.Array, dict]:
    """(the mean loss over the labelled steps (0 where none), its metrics). states: s_t
    `[T, B, H]`, differentiable (the gradient reaches the encoder through them)."""
    prediction = head(config).apply(head_params, states)
    mask = labels.mask.astype(jnp.float32)
    count = jnp.sum(mask)
    loss = jnp.sum(per_step_loss(config.aux_target, prediction, labels.y) * mask) / jnp.maximum(count, 1.0)
    return loss, {"losses/aux_loss": loss, "charts/aux_labelled": count}


def init(config: Config, key: chex.PRNGKey, optimizer) -> Optional[TargetState]:
    """The head's initial TargetState (None without a target)."""
    if config.aux_target == "none":
        return None
    params = head(config).init(key, jnp.zeros((config.hidden_size,), jnp.float32))
    return TargetState(params, optimizer.init(params))
