"""The imagination probes run over trained models (`experiments.probe` runs them on a folder,
`experiments.paper` on its sweeps): test SR under each condition of i_tau
(`experiments.reporting.probing.CONDITIONS`), f_w against its targets on held-out items,
f_w's training options replayed (`FIT_OPTIONS`), where the sub-goal falls.
`experiments.analysis.probes` has the functions; `experiments.reporting.probing` writes the Markdown
of what `probe` returns."""

from __future__ import annotations

import dataclasses
import functools
import time

import jax
import jax.numpy as jnp
import numpy as np

from experiments.analysis.probes import (
    fit_imagination_offline,
    halves,
    imagination_fit,
    only_fit_items,
    r_squared,
    replay_online_fit,
    shuffled,
    signal_to_noise,
    subgoal_position_histogram,
)
from experiments.reporting.probing import FIT_OPTIONS, KEEP_STATE  # noqa: F401 (probes.FIT_OPTIONS too)
from experiments.running import selection
from experiments.running.models import Model
from foresit_jax.evaluate import Evaluator, agent_params
from foresit_jax.imagination import make_imagination_optimizer
from foresit_jax.networks import build
from foresit_jax.train import collect_subgoal_items


def sr_conditions(model: Model, evaluator, episodes: int, shuffled) -> dict[str, float]:
    """Test SR (%) of one model under each applicable condition (`probing.CONDITIONS`); `shuffled`:
    the config's networks with i_tau shuffled across episodes (`experiments.analysis.probes.shuffled`; one per
    config: its rollout compiles once)."""
    config = model.config
    key = selection.test_key(model.seed)
    training_end = agent_params(model.state, config.sigma2_max, "training_end").noise_variance
    trained = model.selected._replace(noise_variance=training_end)
    untrained_w = model.trainer.init(selection.run_key(model.seed)).imagination_params

    def sr(params, **kw):
        return evaluator.evaluate(params, config, "test", key, episodes, **kw)["overall"]["SR"]

    out = {"trained": sr(trained)}
    if config.pieces.imagination_variant.uses_imagination:
        out["noise off"] = sr(trained._replace(noise_variance=jnp.zeros_like(training_end)))
        if config.pieces.imagination_variant.trains_imagination:  # the oracle's i_tau owes nothing to f_w
            out["untrained f_w"] = sr(trained._replace(imagination_params=untrained_w))
        out["shuffled"] = sr(trained, agent=shuffled)
        # At the training-end noise most of i_tau's variance can be noise: shuffling then
        # changes little of what the policy sees. Without the noise, only i_tau's content moves.
        out["shuffled, noise off"] = sr(trained._replace(noise_variance=jnp.zeros_like(training_end)), agent=shuffled)
    if config.pieces.greedy_evaluation:
        out["sampled actions"] = sr(trained, greedy=False)
    return out


def fit_options(model: Model, w_init, items, passes: int) -> dict[str, float]:
    """R^2 over the mean on the held-out items of f_w trained by each of `FIT_OPTIONS`
    (`probes.replay_online_fit`) from `w_init` on the fit items of `items` ((s_0, goal,
    subgoal, add), each `[windows, T, B, ...]`); NaN for an option this run's Config
    cannot take (a batch that does not divide its buffer)."""
    s_0, goal, subgoal, add = (x.reshape((-1,) + x.shape[2:]) for x in items)  # steps in time order
    add = add.astype(bool)
    fit, held = halves(int(add.sum()))
    mean = subgoal[add][fit].mean(axis=0)
    out = {}
    for name, change in FIT_OPTIONS.items():
        change = dict(change)
        keep_state = change.pop(KEEP_STATE, False)
        try:
            config = dataclasses.replace(model.config, **change)
        except ValueError:  # e.g. a batch that does not divide this run's buffer: not applicable
            out[name] = float("nan")
            continue
        optimizer = make_imagination_optimizer(config.imagination_optimizer, config.imagination_lr)
        w = replay_online_fit(
            model.trainer.networks.imagine,
            w_init,
            s_0,
            goal,
            subgoal,
            only_fit_items(add),
            optimizer,
            config.imagination_epochs,
            config.buffer_size,
            passes,
            config.imagination_batch,
            keep_state,
        )
        predicted = np.asarray(model.trainer.networks.imagine(w, s_0[add][held], goal[add][held]))
        out[name] = r_squared(predicted, subgoal[add][held], mean)
    return out


def imagination_items(model: Model, windows: int, options_passes: int = 0) -> dict:
    """f_w's fit, its signal beside the noise, and the sub-goal positions, on the items of
    `windows` fresh training windows (`foresit_jax.train.collect_subgoal_items`); with
    `options_passes`, `fit_options` too."""
    trainer, state = model.trainer, model.state
    state = state._replace(key=jax.random.fold_in(state.key, 7))  # windows f_w never saw
    collect = jax.jit(functools.partial(collect_subgoal_items, trainer), static_argnums=2)
    items, (t_star, step) = jax.tree.map(np.asarray, collect(state, trainer.env_params, windows))
    s_0, goal, subgoal, add = items
    add = add.astype(bool)
    out = {"subgoal": subgoal_position_histogram(t_star[add], step[add])}
    if model.config.pieces.imagination_variant.trains_imagination and add.sum() >= 4:
        s_0, goal, subgoal = s_0[add], goal[add], subgoal[add]
        predicted = np.asarray(trainer.networks.imagine(state.imagination_params, s_0, goal))
        w_init = trainer.init(selection.run_key(model.seed)).imagination_params  # the run's own initial f_w
        offline, steps = fit_imagination_offline(trainer.networks.imagine, w_init, s_0, goal, subgoal)
        out["fit"] = imagination_fit(
            predicted, subgoal, goal, s_0=s_0, offline=np.asarray(trainer.networks.imagine(offline, s_0, goal))
        )
        out["fit"]["offline_steps"] = steps
        if options_passes:
            out["fit_options"] = fit_options(model, w_init, items, options_passes)
        variance = float(agent_params(state, model.config.sigma2_max, "training_end").noise_variance)
        out["signal"] = signal_to_noise(predicted, variance)
    return out


def probe(models: dict[str, list[Model]], episodes: int, windows: int, options_passes: int = 0) -> dict:
    """{method: [per seed: {"seed", "sr": `sr_conditions`, "items": `imagination_items`}]}."""
    report, evaluators, t0 = {}, {}, time.time()
    for method, seeds in models.items():
        report[method] = []
        shuffled_nets = shuffled(build(seeds[0].config))
        for model in seeds:
            where = Evaluator.scenes_of(model.config)
            evaluator = evaluators.setdefault(where, Evaluator(*where))
            sr = sr_conditions(model, evaluator, episodes, shuffled_nets)
            items = imagination_items(model, windows, options_passes)
            report[method].append({"seed": model.seed, "sr": sr, "items": items})
            print(f"probe {method} seed {model.seed}: {sr} ({time.time() - t0:.0f} s)", flush=True)
    return report
