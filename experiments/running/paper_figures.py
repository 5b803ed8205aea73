"""The paper report's figures and rows that read trained models back from its sweeps'
run folders (`experiments.paper` writes the report): Figure 3's trajectories, Figure 4's
t-SNE, and the sampled-action evaluation of a sweep's methods."""

from __future__ import annotations

import functools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from envs.catalog import ROOM_TYPES, categories
from experiments.running import selection, sweeps
from experiments import rundir
from experiments.running.models import models_of_sweep
from foresit_jax import rollout as rollout_lib
from foresit_jax.evaluate import Evaluator, base_acting
from foresit_jax.networks import build
from foresit_jax.rollout import ActOptions, BoundEnv


def trajectories_figure(loaded: dict, seed: int, candidates: int, path: Path) -> str:
    """Figure 3: two methods' models, `loaded` {method: (config, selected AgentParams)},
    play the same test episodes of seed `seed` (`selection.test_key`), one per room type:
    the first of `candidates` whose L^g >= 5 (a fixed rule, not a choice of good-looking
    ones); each method acts by its own evaluation protocol. Draws them side by side into
    `path`; returns one line per episode."""
    from envs.render import render_topdown  # matplotlib, imported at its top
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    evaluator = Evaluator.for_config(next(iter(loaded.values()))[0])
    env, n = evaluator.env, candidates
    key = selection.test_key(seed)
    rooms = next(iter(loaded.values()))[0].room_types or ROOM_TYPES
    rollouts = {
        m: jax.jit(
            functools.partial(
                rollout_lib.rollout,
                build(config),
                act=base_acting(config).act,
                options=ActOptions(greedy=config.pieces.greedy_evaluation),
            ),
            static_argnames="num_steps",
        )
        for m, (config, _) in loaded.items()
    }
    replay = jax.jit(functools.partial(replay_positions, env))
    panels, lines = [], []
    for room, k in zip(rooms, jax.random.split(key, len(rooms))):
        env_params = evaluator.room_params("test", room)
        num_steps = int(jnp.max(env_params.max_steps))
        reset_keys = jax.random.split(jax.random.fold_in(k, 0), n)
        _, start = jax.vmap(env.reset, in_axes=(0, None))(reset_keys, env_params)
        long = np.flatnonzero(np.asarray(start.optimal_length) >= 5)
        if not len(long):
            continue
        i = int(long[0])
        row = []
        for method, (config, params) in loaded.items():
            acting = params._replace(noise_variance=jnp.full((n,), params.noise_variance))
            traj = rollouts[method](acting, BoundEnv(env, env_params), k, num_steps=num_steps, reset_keys=reset_keys)
            actions, valid, success = (np.asarray(x)[:, i] for x in (traj.actions, traj.valid, traj.success))
            steps = int(valid.sum())
            poses = np.asarray(replay(env_params, reset_keys[i], actions))[: steps + 1]
            ok = bool((success & valid).any())
            state = jax.tree.map(lambda x: x[i], start)
            title = f"{method}: {'success' if ok else 'failure'}, {steps} actions (L^g {int(state.optimal_length)})"
            row.append(render_topdown(env_params, int(state.scene), state=state, trajectory=poses, title=title))
            lines.append(
                f"{room} {method}: {'success' if ok else 'failure'} in {steps} actions, L^g {int(state.optimal_length)}"
            )
        panels.append(row)
    fig = Figure(figsize=(10, 4.2 * len(panels)))
    FigureCanvasAgg(fig)
    for r, row in enumerate(panels):
        for c, image in enumerate(row):
            ax = fig.add_subplot(len(panels), 2, 2 * r + c + 1)
            ax.imshow(image)
            ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    return "; ".join(lines)


def replay_positions(env, env_params, reset_key, actions):
    """[T + 1, 2] the cells the agent stood on, the start included, for actions `[T]` (the
    dynamics are deterministic: the episode replayed from its reset key and actions; the
    rows after the episode's last action are the caller's to drop)."""
    _, state = env.reset(reset_key, env_params)

    def step(state, action):
        _, state, *_ = env.step_env(reset_key, state, action, env_params)
        return state, state.agent_pos

    _, cells = jax.lax.scan(step, state, actions)
    return jnp.concatenate([state.agent_pos[None], cells])


def tsne_figure(config, trainer, state, items, path: Path, points: int, seed: int) -> int:
    """Figure 4: t-SNE of f_w([s_0 : g_tau]) and of the critic-selected sub-goals ŝ_tau of
    `items` (`cvae_comparison.collect_items`: successful training episodes of the first
    seed's last agent, what f_w learns from), coloured by target category; returns the
    number of items drawn."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from sklearn.manifold import TSNE

    method = config.method
    s_0, goal, subgoal = (x[:points] for x in items)
    n = len(s_0)
    if n < 5:
        return n
    imagined = np.asarray(build(config).imagine(state.imagination_params, s_0, goal))
    vectors = np.asarray(trainer.env_params.bank.target_vectors)
    category = np.argmin(((goal[:, None, :] - vectors[None]) ** 2).sum(-1), axis=1)
    names = categories(config.setup)
    points = TSNE(perplexity=min(30.0, (2 * n - 1) / 3), init="pca", random_state=seed).fit_transform(
        np.concatenate([imagined, subgoal])
    )
    fig = Figure(figsize=(7, 6))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    cmap = __import__("matplotlib").colormaps["tab20"]
    for j, c in enumerate(np.unique(category)):
        m = category == c
        ax.scatter(*points[:n][m].T, marker="o", s=14, color=cmap(j % 20), label=names[c])
        ax.scatter(*points[n:][m].T, marker="x", s=14, color=cmap(j % 20))
    ax.set_title(f"{method}: imagined f_w (o) and selected sub-goals (x), {n} items")
    ax.legend(fontsize=6, ncol=2, markerscale=0.8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return n


def sampled_results(folder: Path, methods) -> dict[str, list[dict]]:
    """{method: [per seed: {"seed", "overall"}]}: each finished seed's selected model of a
    sweep's `methods` on its own test episodes (`selection.test_key`, the sweep's test
    episodes per room type) with actions sampled from the policy. For a method evaluated
    greedily (ORG's protocol) these are the episodes its report row played, with the other
    action rule; for one evaluated sampled, its row's own numbers again."""
    out, evaluators = {}, {}
    for method, models in models_of_sweep(folder, tuple(methods)).items():
        episodes = sweeps.episodes_per_room(folder, "test", method)
        out[method] = []
        for model in models:
            where = Evaluator.scenes_of(model.config)
            evaluator = evaluators.setdefault(where, Evaluator(*where))
            result = evaluator.evaluate(
                model.selected, model.config, "test", selection.test_key(model.seed), episodes, greedy=False
            )
            out[method].append({"seed": model.seed, "overall": rundir.jsonable(result["overall"])})
    return out
