"""Probes of a trained agent's imagination, as pure functions (the CLI is `experiments.probe`).

Three questions, each answerable from a finished run without training:

* Does the policy use i_tau? Evaluate the same model on the same episodes with i_tau
  from the trained f_w, with the noise off, from an untrained f_w, and shuffled across
  episodes (`shuffled`: each episode imagines from another episode's s_0 and
  target). A policy that ignores i_tau scores the same under all four.
* Does f_w predict its targets? `imagination_fit`: on sub-goal items the agent's own
  successful episodes offer (held out: f_w never trained on them), f_w's error against
  predicting the targets' mean and against predicting each target category's mean (fit
  on one half of the items, scored on the other), as R^2, and how large f_w's signal is
  beside the noise the policy sees (`signal_to_noise`).
* Where does the sub-goal fall in its episode? `subgoal_position_histogram`: t*/T over
  the successful episodes (T the Done step), and the share with t* = T (the Done step's
  own state).

And one of any trained agent (the CLI is `experiments.failures`): how do its episodes end?
`replay_oracle` replays episodes through the environment's oracle, `episode_endings`
sorts them into successes, Dones that failed (when, how far from success, in which room)
and time-outs, with the policy's probability of Done where it would succeed and where not.
"""

from __future__ import annotations

import dataclasses

import chex
import jax
import jax.numpy as jnp
import numpy as np
import optax

from foresit_jax import imagination
from foresit_jax.networks import Networks


def shuffled(nets: Networks) -> Networks:
    """`nets` acting with each lane's i_tau imagined from the previous lane's inputs (lane b
    gets lane b - 1's s_t and target, cyclically; the privileged oracle's goal-view latent
    the same way): i_tau shuffled across episodes, with the distribution of f_w's outputs
    kept. Only for probing a trained model (`rollout`'s i_tau reads `Networks.permute`)."""
    return dataclasses.replace(nets, permute=lambda x: jnp.roll(x, 1, axis=0))


def r_squared(predicted: np.ndarray, target: np.ndarray, reference: np.ndarray) -> float:
    """1 - SSE(predicted) / SSE(reference), summed over items and dimensions: the share of
    the error of `reference` (e.g. the targets' mean) that `predicted` removes."""
    sse = float(np.sum((np.asarray(target) - predicted) ** 2))
    return 1.0 - sse / max(float(np.sum((np.asarray(target) - reference) ** 2)), 1e-12)


def smooth_l1(predicted: np.ndarray, target: np.ndarray) -> float:
    """Mean smooth-L1 (Huber, delta 1), f_w's own loss (`foresit_jax.imagination.smooth_l1`)."""
    d = np.abs(np.asarray(predicted) - np.asarray(target))
    return float(np.mean(np.where(d < 1.0, 0.5 * d**2, d - 0.5)))


def halves(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The probe's split of n items: (fit: the even ones, held out: the odd ones)."""
    return np.arange(0, n, 2), np.arange(1, n, 2)


RIDGE_ALPHAS = tuple(10.0 ** np.arange(-4, 5))


def ridge_fit(x: np.ndarray, y: np.ndarray, alphas=RIDGE_ALPHAS) -> tuple[np.ndarray, np.ndarray, float]:
    """Ridge regression of y `[N, H]` on x `[N, F]` with an intercept (not penalised), the
    penalty chosen among `alphas` by exact leave-one-out error on these items (the hat
    matrix of the centred problem: residual_i / (1 - h_ii)). Returns (W `[F, H]`, b `[H]`,
    alpha), the prediction being x @ W + b."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    mx, my = x.mean(0), y.mean(0)
    xc, yc = x - mx, y - my
    u, s, vt = np.linalg.svd(xc, full_matrices=False)
    uty = u.T @ yc
    best = None
    for alpha in alphas:
        shrink = s**2 / (s**2 + alpha)
        fitted = u @ (shrink[:, None] * uty)
        # with the intercept, the centred hat matrix plus 1/N is the leave-one-out's
        h = np.sum(u**2 * shrink, axis=1) + 1.0 / len(x)
        loo = float(np.sum(((yc - fitted) / np.maximum(1.0 - h, 1e-9)[:, None]) ** 2))
        if best is None or loo < best[0]:
            best = (loo, alpha)
    alpha = best[1]
    w = vt.T @ ((s / (s**2 + alpha))[:, None] * uty)
    return w, my - mx @ w, float(alpha)


def imagination_fit(
    predicted: np.ndarray,
    target: np.ndarray,
    goal: np.ndarray,
    s_0: np.ndarray | None = None,
    offline: np.ndarray | None = None,
) -> dict[str, float]:
    """How well f_w's predictions `[N, H]` match the sub-goals `[N, H]` of items whose
    targets are `goal [N, D]`, against baselines fit on the even items and scored, as f_w
    is, on the odd ones (`halves`): the targets' mean, and each target category's mean (a
    category is a distinct goal vector; one unseen in the even half gets the mean).
    Returns items, f_w's smooth-L1 and R^2 over the mean, the category baseline's R^2
    over the mean, and f_w's R^2 over the category baseline (> 0: f_w knows more than the
    target category alone).

    With f_w's inputs `s_0 [N, H]`, what those inputs tell (each as R^2 over the mean, on
    the odd items): `identity_r2_over_mean`, the sub-goal predicted as s_0 itself (exact
    where the critic's sub-goal is the start, f_w's own input); `ridge_r2_over_mean`,
    ridge regression on [s_0 : g] fit on the even items (`ridge_fit`, its penalty in
    `ridge_alpha`). With `offline` `[N, H]`, the predictions of f_w's architecture trained
    offline on the even items (`fit_imagination_offline`): `offline_r2_over_mean`.
    Where these beat the category mean and f_w does not, f_w is fitted worse than its
    inputs allow."""
    predicted, target, goal = (np.asarray(x, np.float64) for x in (predicted, target, goal))
    fit, held = halves(len(target))
    mean = target[fit].mean(axis=0)
    categories, index = np.unique(goal, axis=0, return_inverse=True)
    index = index.reshape(-1)
    category_mean = np.tile(mean, (len(categories), 1))
    for c in range(len(categories)):
        members = fit[index[fit] == c]
        if len(members):
            category_mean[c] = target[members].mean(axis=0)
    by_category = category_mean[index[held]]
    out = {
        "items": int(len(target)),
        "smooth_l1": smooth_l1(predicted[held], target[held]),
        "r2_over_mean": r_squared(predicted[held], target[held], mean),
        "category_r2_over_mean": r_squared(by_category, target[held], mean),
        "r2_over_category": r_squared(predicted[held], target[held], by_category),
    }
    if s_0 is not None:
        s_0 = np.asarray(s_0, np.float64)
        out["identity_r2_over_mean"] = r_squared(s_0[held], target[held], mean)
        x = np.concatenate([s_0, goal], axis=-1)
        w, b, out["ridge_alpha"] = ridge_fit(x[fit], target[fit])
        out["ridge_r2_over_mean"] = r_squared(x[held] @ w + b, target[held], mean)
    if offline is not None:
        out["offline_r2_over_mean"] = r_squared(np.asarray(offline, np.float64)[held], target[held], mean)
    return out


def fit_imagination_offline(
    imagine, w_init, s_0, goal, target, steps: int = 3000, learning_rate: float = 1e-3, check_every: int = 50
):
    """f_w's architecture (`imagine(w, s_0, goal)`, from `w_init`) trained offline on the
    even items of (s_0, goal, target) (`halves`) with f_w's own loss (smooth-L1), full
    batch, Adam at `learning_rate`, up to `steps` steps: as well fitted as these items
    allow, beside the online f_w, which sees each item in one lane's buffer of M, one step
    per item. One even item in five is held back for early stopping (every
    `check_every` steps; the parameters of its lowest loss are returned), so the odd items
    the probe scores stay unseen. Returns (parameters, steps taken to the best)."""
    loss_of = imagination.smooth_l1

    fit, _ = halves(len(target))
    stop, train = fit[::5], np.setdiff1d(fit, fit[::5])
    data = [jnp.asarray(np.asarray(x)[i]) for i in (train, stop) for x in (s_0, goal, target)]
    optimizer = optax.adam(learning_rate)

    def loss(w, s, g, y):
        return jnp.mean(loss_of(imagine(w, s, g), y))

    @jax.jit
    def run(w, opt, s, g, y):
        def step(carry, _):
            w, opt = carry
            grads = jax.grad(loss)(w, s, g, y)
            updates, opt = optimizer.update(grads, opt, w)
            return (optax.apply_updates(w, updates), opt), None

        return jax.lax.scan(step, (w, opt), None, length=check_every)[0]

    check = jax.jit(loss)
    w, opt = w_init, optimizer.init(w_init)
    best = (float(check(w, *data[3:])), w, 0)
    for done in range(check_every, steps + 1, check_every):
        w, opt = run(w, opt, *data[:3])
        held = float(check(w, *data[3:]))
        if held < best[0]:
            best = (held, w, done)
    return best[1], best[2]


def replay_online_fit(
    imagine,
    w_start,
    s_0,
    goal,
    subgoal,
    add,
    optimizer,
    epochs: int,
    buffer_size: int,
    passes: int = 1,
    batch: int = 1,
    keep_optimizer_state: bool = False,
):
    """f_w trained from `w_start` as training trains it (`imagination.buffer_add` and
    `train_on_full_buffers`, step by step in time order, one buffer of `buffer_size` per
    lane, `epochs` passes of one `optimizer` step per item, a fresh optimiser state per
    buffer (with `keep_optimizer_state`, one state kept across buffers instead: not a
    training option), `batch` items a step), on a stream of items `[S, B, ...]` (S steps of B lanes; `add [S, B]`: which
    steps offer their item), streamed `passes` times: how well the online procedure fits
    these items at a fixed encoder, to hold against `fit_imagination_offline` on the same
    items. Jitted per call; returns the parameters."""

    lanes = add.shape[1]
    buffers = jax.tree.map(
        lambda x: jnp.broadcast_to(x, (lanes,) + x.shape),
        imagination.buffer_init(buffer_size, s_0.shape[-1], goal.shape[-1]),
    )
    stream = tuple(jnp.asarray(np.concatenate([np.asarray(x)] * passes)) for x in (s_0, goal, subgoal, add))

    @jax.jit
    def run(w, buffers, stream):
        def step(carry, item):
            w, buffers, state = carry
            buffers = jax.vmap(imagination.buffer_add)(buffers, *item)
            w, buffers, _, state = imagination.train_on_full_buffers(
                w, buffers, imagine, optimizer, epochs, batch, state
            )
            return (w, buffers, state), None

        state = optimizer.init(w) if keep_optimizer_state else None
        return jax.lax.scan(step, (w, buffers, state), stream)[0][0]

    return run(w_start, buffers, stream)


def only_fit_items(add: np.ndarray) -> np.ndarray:
    """`add` (any shape) keeping only the items `halves` puts in the fit half: the even
    ones in row-major order, the order in which `x[add]` lists them."""
    add = np.asarray(add, bool)
    rank = np.cumsum(add.reshape(-1)).reshape(add.shape) - 1
    return add & (rank % 2 == 0)


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
        return {
            "episodes": 0,
            "edges": np.linspace(0, 1, bins + 1).tolist(),
            "shares": [float("nan")] * bins,
            "at_done": float("nan"),
        }
    ratio = np.where(total > 0, t / np.maximum(total, 1), 1.0)
    counts, edges = np.histogram(ratio, bins=bins, range=(0.0, 1.0))
    return {
        "episodes": n,
        "edges": edges.tolist(),
        "shares": (counts / n).tolist(),
        "at_done": float(np.mean(t == total)),
    }


def replay_oracle(env, env_params, reset_keys: chex.Array, actions: chex.Array) -> tuple[chex.Array, chex.Array]:
    """Episodes replayed from their reset keys `[B, ...]` and actions `[B, T]` (the dynamics
    are deterministic): `d [B, T]`, the oracle's shortest number of actions to success
    (Done counted) before each action, and `in_room [B, T]`, whether the agent then stands
    in the target's room. Steps after an episode's end are the caller's to drop. Jittable."""

    def one(reset_key, acts):
        _, state = env.reset(reset_key, env_params)

        def step(state, action):
            facts = (env.shortest_path_length(state, env_params), env.in_target_room(state, env_params))
            _, state, *_ = env.step_env(reset_key, state, action, env_params)
            return state, facts

        return jax.lax.scan(step, state, acts)[1]

    return jax.vmap(one)(reset_keys, actions)


EARLY_STEPS = 5  # `episode_endings`: a Done within this many actions of the start is "early"


def episode_endings(valid, success, actions, p_done, d, in_room, done_action: int = 5) -> dict:
    """How episodes end, from `[B, T]` arrays (batch-major): `valid` (the step belongs to the
    episode), `success`, `actions`, `p_done` (the policy's probability of Done at the step),
    and `replay_oracle`'s `d` and `in_room`. Returns the shares of successes, failed Dones
    and time-outs (every episode is one of them); for the failed Dones, the actions taken
    (median), the share said within `EARLY_STEPS` actions, the oracle's actions to success
    at the Done (median) and the share said in the target's room; the mean probability of
    Done at the steps where Done would succeed (d = 1) and where it would not, and at the
    first `EARLY_STEPS` steps where it would not; and the shares again for the episodes
    that start in the target's room and for those that start away."""
    valid, success, in_room = (np.asarray(x, bool) for x in (valid, success, in_room))
    actions, p_done, d = np.asarray(actions), np.asarray(p_done, np.float64), np.asarray(d)
    steps = valid.sum(1)
    if np.any(steps < 1):
        raise ValueError("episode_endings: every episode has at least one step")
    rows = np.arange(len(steps))
    last = steps - 1
    won = (success & valid).any(1)
    failed_done = ~won & (actions[rows, last] == done_action)
    kind = np.where(won, "success", np.where(failed_done, "failed Done", "time-out"))
    if np.any(d[rows, last][failed_done] <= 1):
        raise ValueError("episode_endings: a failed Done where the oracle says Done would succeed (d = 1)")

    def shares(mask):
        n = int(mask.sum())
        return {
            "episodes": n,
            **{
                k: float(np.mean(kind[mask] == k)) if n else float("nan")
                for k in ("success", "failed Done", "time-out")
            },
        }

    def mean(x):
        return float(np.mean(x)) if len(x) else float("nan")

    early = np.arange(valid.shape[1])[None, :] < EARLY_STEPS
    at = failed_done
    out = {
        "all": shares(np.ones(len(steps), bool)),
        "failed Done": {
            "episodes": int(at.sum()),
            "median actions": float(np.median(steps[at])) if at.any() else float("nan"),
            "early share": mean(steps[at] <= EARLY_STEPS),
            "median d at Done": float(np.median(d[rows, last][at])) if at.any() else float("nan"),
            "in target room share": mean(in_room[rows, last][at]),
        },
        "p_done": {
            "would succeed": mean(p_done[valid & (d == 1)]),
            "would fail": mean(p_done[valid & (d > 1)]),
            "would fail, early": mean(p_done[valid & (d > 1) & early]),
        },
        "start in target room": shares(in_room[:, 0]),
        "start away": shares(~in_room[:, 0]),
    }
    return out
