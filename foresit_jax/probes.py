"""Probes of a trained agent's imagination, as pure functions (the CLI is `experiments.probe`).

Three questions, each answerable from a finished run without training:

* Does the policy use i_tau? Evaluate the same model on the same episodes with i_tau
  from the trained f_w, with the noise off, from an untrained f_w, and shuffled across
  episodes (`ShuffledImagination`: each episode imagines from another episode's s_0 and
  target). A policy that ignores i_tau scores the same under all four.
* Does f_w predict its targets? `imagination_fit`: on sub-goal items the agent's own
  successful episodes offer (held out: f_w never trained on them), f_w's error against
  predicting the targets' mean and against predicting each target category's mean (fit
  on one half of the items, scored on the other), as R^2, and how large f_w's signal is
  beside the noise the policy sees (`signal_to_noise`).
* Where does the sub-goal fall in its episode? `subgoal_position_histogram`: t*/T over
  the successful episodes (T the Done step), and the share with t* = T (the Done step's
  own state).
"""

from __future__ import annotations

import chex
import jax.numpy as jnp
import numpy as np

from foresit_jax.agent import Agent


class ShuffledImagination(Agent):
    """An `Agent` whose f_w imagines each lane's i_tau from the next lane's inputs (s_t and
    target of lane b - 1, cyclically): i_tau shuffled across episodes, with the
    distribution of f_w's outputs kept. Only for probing a trained model."""

    def imagine(self, w_params, s_0: chex.Array, goal: chex.Array) -> chex.Array:
        return super().imagine(w_params, jnp.roll(s_0, 1, axis=0), jnp.roll(goal, 1, axis=0))


def r_squared(predicted: np.ndarray, target: np.ndarray, reference: np.ndarray) -> float:
    """1 - SSE(predicted) / SSE(reference), summed over items and dimensions: the share of
    the error of `reference` (e.g. the targets' mean) that `predicted` removes."""
    sse = float(np.sum((np.asarray(target) - predicted) ** 2))
    return 1.0 - sse / max(float(np.sum((np.asarray(target) - reference) ** 2)), 1e-12)


def smooth_l1(predicted: np.ndarray, target: np.ndarray) -> float:
    """Mean smooth-L1 (Huber, delta 1), f_w's own loss (`foresit_jax.losses.smooth_l1`)."""
    d = np.abs(np.asarray(predicted) - np.asarray(target))
    return float(np.mean(np.where(d < 1.0, 0.5 * d**2, d - 0.5)))


def imagination_fit(predicted: np.ndarray, target: np.ndarray, goal: np.ndarray) -> dict[str, float]:
    """How well f_w's predictions `[N, H]` match the sub-goals `[N, H]` of items whose
    targets are `goal [N, D]`, against two baselines fit on the even items and scored,
    as f_w is, on the odd ones: the targets' mean, and each target category's mean (a
    category is a distinct goal vector; one unseen in the even half gets the mean).
    Returns items, f_w's smooth-L1 and R^2 over the mean, the category baseline's R^2
    over the mean, and f_w's R^2 over the category baseline (> 0: f_w knows more than the
    target category alone)."""
    predicted, target, goal = (np.asarray(x, np.float64) for x in (predicted, target, goal))
    fit, held = np.arange(0, len(target), 2), np.arange(1, len(target), 2)
    mean = target[fit].mean(axis=0)
    categories, index = np.unique(goal, axis=0, return_inverse=True)
    index = index.reshape(-1)
    category_mean = np.tile(mean, (len(categories), 1))
    for c in range(len(categories)):
        members = fit[index[fit] == c]
        if len(members):
            category_mean[c] = target[members].mean(axis=0)
    by_category = category_mean[index[held]]
    return {
        "items": int(len(target)),
        "smooth_l1": smooth_l1(predicted[held], target[held]),
        "r2_over_mean": r_squared(predicted[held], target[held], mean),
        "category_r2_over_mean": r_squared(by_category, target[held], mean),
        "r2_over_category": r_squared(predicted[held], target[held], by_category),
    }


def signal_to_noise(predicted: np.ndarray, noise_variance: float) -> dict[str, float]:
    """How much of i_tau's variance is signal: the variance of f_w's outputs across
    episodes (mean over dimensions) beside the variance of the noise added to them (Eq. 7);
    `signal_share` = signal / (signal + noise)."""
    signal = float(np.mean(np.var(np.asarray(predicted, np.float64), axis=0)))
    noise = float(noise_variance)
    return {"signal_variance": signal, "noise_variance": noise, "signal_share": signal / max(signal + noise, 1e-12)}


def subgoal_position_histogram(subgoal_step: np.ndarray, done_step: np.ndarray, bins: int = 5) -> dict:
    """t*/T of each successful episode (sub-goal step t*, Done step T, both 0-based, T >= t*):
    the share in each of `bins` equal bins of [0, 1] (T = 0 counts as 1), the share with
    t* = T, and the number of episodes."""
    t, total = np.asarray(subgoal_step, np.float64), np.asarray(done_step, np.float64)
    if np.any(t > total) or np.any(t < 0):
        raise ValueError("a sub-goal lies outside its episode (t* > T or t* < 0)")
    n = len(t)
    if n == 0:
        return {"episodes": 0, "edges": np.linspace(0, 1, bins + 1).tolist(), "shares": [float("nan")] * bins,
                "at_done": float("nan")}  # fmt: skip
    ratio = np.where(total > 0, t / np.maximum(total, 1), 1.0)
    counts, edges = np.histogram(ratio, bins=bins, range=(0.0, 1.0))
    return {"episodes": n, "edges": edges.tolist(), "shares": (counts / n).tolist(), "at_done": float(np.mean(t == total))}
