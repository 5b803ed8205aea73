"""Did a target's head learn? (docs/plans/imagination_targets.md, stage 1's third measure.)

For each seed of a run folder whose arm has an auxiliary target (`Config.aux_target`), the
final training state's agent plays whole test episodes in the environment wrapped with the
target's labels (`foresit_jax.imagination.label_env`), and its head (`RunnerState.targets`)
predicts each labelled step's target from s_t. Against a predictor of the mean label:

* ``compass``: the mean angular error of the predicted bearing (degrees), beside the mean
  predictor's (the mean label's bearing), and the R² of the distance d / G;
* ``goal_view`` and ``success``: the R² of the latent (pooled over its dimensions); and the
  spread of the labels across episodes (each episode's first labelled step; the mean over
  dimensions of their standard deviation) beside the spread of the agent's own states over
  the same steps: a target whose spread is a small share of the states' is near a constant.

A head is "learned" where it beats the mean (R² > 0; for the compass, a smaller angular
error than the mean's too); one that does not is reported "not learned", never "does not
help" (the plan).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from foresit_jax import imagination, rollout
from foresit_jax.train import make_env


def r2(y: np.ndarray, prediction: np.ndarray) -> float:
    """1 - SSE / SST over the rows of `y` `[N, K]` (pooled over K), against their mean."""
    sst = float(np.sum((y - y.mean(axis=0)) ** 2))
    return float(1.0 - np.sum((prediction - y) ** 2) / sst) if sst > 0 else float("nan")


def angular_error(true_cos_sin: np.ndarray, predicted: np.ndarray) -> float:
    """Mean absolute angle (degrees) between the bearings of `true_cos_sin` `[N, 2]` and of
    `predicted` `[N, 2]` (its own atan2, so any scale)."""
    truth = np.arctan2(true_cos_sin[:, 1], true_cos_sin[:, 0])
    guess = np.arctan2(predicted[:, 1], predicted[:, 0])
    return float(np.degrees(np.mean(np.abs(np.angle(np.exp(1j * (guess - truth)))))))


def head_metrics(target: str, y: np.ndarray, prediction: np.ndarray, episode_labels, episode_states) -> dict:
    """The measures above from the labelled steps' labels `y` and the head's `prediction`
    `[N, K]`; episode_labels / episode_states `[E, K]`, `[E, H]`: each episode's first labelled
    step (the spread)."""
    if not len(y):
        return {"labelled_steps": 0, "learned": False}
    mean = np.broadcast_to(y.mean(axis=0), y.shape)
    if target == "compass":
        head_err, mean_err = angular_error(y[:, :2], prediction[:, :2]), angular_error(y[:, :2], mean[:, :2])
        r2_d = r2(y[:, 2:], prediction[:, 2:])
        out = {"angular_error": head_err, "angular_error_of_mean": mean_err, "r2_distance": r2_d}
        out["learned"] = bool(head_err < mean_err and r2_d > 0)
    else:
        out = {"r2": r2(y, prediction)}
        out["learned"] = bool(out["r2"] > 0)
        out["label_spread"] = (
            float(np.mean(np.std(episode_labels, axis=0))) if len(episode_labels) > 1 else float("nan")
        )
        out["state_spread"] = (
            float(np.mean(np.std(episode_states, axis=0))) if len(episode_states) > 1 else float("nan")
        )
    out["labelled_steps"] = int(len(y))
    return out


def probe_seed(trainer, state, key, episodes: int) -> dict:
    """`head_metrics` of one seed's final state (unbatched RunnerState with its head) on
    `episodes` test episodes (every room type of the config, in turn)."""
    config, nets = trainer.config, trainer.networks
    env, env_params = make_env(config, split="test", training=False)
    labelled = rollout.BoundEnv(imagination.label_env(config, env), env_params)
    steps = int(jnp.max(env_params.max_steps))
    acting = rollout.AgentParams(state.params, state.imagination_params, jnp.zeros(episodes))

    @jax.jit
    def play(key):
        options = rollout.ActOptions(whole_episodes=True, record_inputs=True)
        traj = rollout.rollout(nets, acting, labelled, key, steps, options)

        def goal_latent(obs):
            return nets.goal_latent(state.params, None, obs)

        labels = imagination.target_labels(config, traj.inputs.obs, traj.states, traj, goal_latent)
        prediction = imagination.target_head(config).apply(state.targets.params, traj.states)
        return traj.states, labels.y, labels.mask, prediction

    states, y, mask, prediction = (np.asarray(x) for x in play(key))
    first = mask & (np.cumsum(mask, axis=0) == 1)  # [T, B]: each episode's first labelled step
    return head_metrics(config.aux_target, y[mask], prediction[mask], y[first], states[first])


def probe_run(trained, episodes: int = 400, seed: int = 0) -> list[dict]:
    """`probe_seed` for every seed of a run folder's models (`models.read_trained`), with the
    test episodes of key `seed` (the same episodes for every seed and arm)."""
    if trained.config.aux_target == "none":
        raise ValueError(f"{trained.config.method}: the arm has no auxiliary target (aux_target='none')")
    key = jax.random.PRNGKey(seed)
    out = []
    for i, run_seed in enumerate(trained.seeds):
        state = jax.tree.map(lambda x: x[i], trained.states)
        out.append({"seed": run_seed, **probe_seed(trained.trainer, state, key, episodes)})
    return out
