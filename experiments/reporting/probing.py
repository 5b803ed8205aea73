"""The imagination probes of a trained model (`experiments.probe` runs them on a folder;
`experiments.paper` on its sweeps): test SR under each condition of i_tau (`CONDITIONS`),
f_w against its targets on held-out items, f_w's training options replayed
(`FIT_OPTIONS`), where the sub-goal falls; `foresit_jax.probes` has the functions, this
module runs them over models and writes the Markdown."""

from __future__ import annotations

import dataclasses
import time

import jax
import jax.numpy as jnp
import numpy as np

from experiments.reporting import stats
from experiments.reporting.tables import markdown_table
from experiments.running import selection
from experiments.running.models import Model

CONDITIONS = ("trained", "noise off", "untrained f_w", "shuffled", "shuffled, noise off", "sampled actions")


# f_w's training options replayed by --fit-options: the run's own first, then one change
# each (Config fields: imagination_optimizer, imagination_lr, imagination_epochs, buffer_size,
# imagination_batch; and `KEEP_STATE`, the replay's own: one optimiser state kept across the
# flushes instead of a fresh one each, which training does not offer).
FIT_OPTIONS = {
    "as trained": {},
    "epochs 1": {"imagination_epochs": 1},
    "epochs 20": {"imagination_epochs": 20},
    "lr 3e-4": {"imagination_lr": 3e-4},
    "lr 3e-3": {"imagination_lr": 3e-3},
    "sgd, lr 1e-2 (Algorithm 1)": {"imagination_optimizer": "sgd", "imagination_lr": 1e-2},
    "M 8": {"buffer_size": 8},
    "M 128": {"buffer_size": 128},
    "batch 8": {"imagination_batch": 8},
    "batch 8, lr 3e-3": {"imagination_batch": 8, "imagination_lr": 3e-3},
    "state kept": {"keep_optimizer_state": True},
    "state kept, lr 3e-4": {"keep_optimizer_state": True, "imagination_lr": 3e-4},
}
KEEP_STATE = "keep_optimizer_state"


def sr_conditions(model: Model, evaluator, episodes: int, shuffled) -> dict[str, float]:
    """Test SR (%) of one model under each applicable condition (`CONDITIONS`); `shuffled`:
    the config's `ShuffledImagination` agent (one per config: its rollout compiles once)."""
    from foresit_jax.evaluate import agent_params

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
    from foresit_jax.imagination import make_imagination_optimizer
    from foresit_jax.probes import halves, only_fit_items, r_squared, replay_online_fit

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
        w = replay_online_fit(model.trainer.agent.imagine, w_init, s_0, goal, subgoal, only_fit_items(add), optimizer,
                              config.imagination_epochs, config.buffer_size, passes, config.imagination_batch,
                              keep_state)  # fmt: skip
        predicted = np.asarray(model.trainer.agent.imagine(w, s_0[add][held], goal[add][held]))
        out[name] = r_squared(predicted, subgoal[add][held], mean)
    return out


def imagination_items(model: Model, windows: int, options_passes: int = 0) -> dict:
    """f_w's fit, its signal beside the noise, and the sub-goal positions, on the items of
    `windows` fresh training windows (`Trainer.collect_subgoal_items`); with
    `options_passes`, `fit_options` too."""
    from foresit_jax.evaluate import agent_params
    from foresit_jax.probes import fit_imagination_offline, imagination_fit, signal_to_noise, subgoal_position_histogram

    trainer, state = model.trainer, model.state
    state = state._replace(key=jax.random.fold_in(state.key, 7))  # windows f_w never saw
    collect = jax.jit(trainer.collect_subgoal_items, static_argnums=2)
    items, (t_star, step) = jax.tree.map(np.asarray, collect(state, trainer.env_params, windows))
    s_0, goal, subgoal, add = items
    add = add.astype(bool)
    out = {"subgoal": subgoal_position_histogram(t_star[add], step[add])}
    if model.config.pieces.imagination_variant.trains_imagination and add.sum() >= 4:
        s_0, goal, subgoal = s_0[add], goal[add], subgoal[add]
        predicted = np.asarray(trainer.agent.imagine(state.imagination_params, s_0, goal))
        w_init = trainer.init(selection.run_key(model.seed)).imagination_params  # the run's own initial f_w
        offline, steps = fit_imagination_offline(trainer.agent.imagine, w_init, s_0, goal, subgoal)
        out["fit"] = imagination_fit(predicted, subgoal, goal, s_0=s_0,
                                     offline=np.asarray(trainer.agent.imagine(offline, s_0, goal)))  # fmt: skip
        out["fit"]["offline_steps"] = steps
        if options_passes:
            out["fit_options"] = fit_options(model, w_init, items, options_passes)
        variance = float(agent_params(state, model.config.sigma2_max, "training_end").noise_variance)
        out["signal"] = signal_to_noise(predicted, variance)
    return out


def _fmt(x, digits: int = 1) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def markdown(report: dict, episodes: int, windows: int, level: int = 1) -> str:
    h = "#" * level
    md = [f"{h} Imagination probes\n\nTest SR (%) of each seed's selected model on the same {episodes} test episodes "
          "per room type under each condition; each condition paired with `trained` over the seeds "
          "(difference [95% interval]).\n"]  # fmt: skip
    for method, per_seed in report.items():
        seeds = [r["seed"] for r in per_seed]
        md.append(f"{h}# {method} (seeds {', '.join(map(str, seeds))})\n")
        conditions = [c for c in CONDITIONS if c in per_seed[0]["sr"]]
        rows = []
        for c in conditions:
            values = [r["sr"][c] for r in per_seed]
            s = stats.summary(values)
            pair = stats.paired([r["sr"]["trained"] for r in per_seed], values) if c != "trained" else None
            diff = "" if pair is None else f"{pair['diff']:+.1f} [{_fmt(pair['ci_low'])}, {_fmt(pair['ci_high'])}]"
            rows.append([c, " / ".join(_fmt(v) for v in values), f"{_fmt(s['mean'])} ± {_fmt(s['std'])}", diff])
        md.append(markdown_table(rows, ["condition", "SR per seed", "mean ± std", "minus trained"]) + "\n")
        fits = [r["items"].get("fit") for r in per_seed]
        if all(fits):
            cells = []
            for r in per_seed:
                f, g = r["items"]["fit"], r["items"]["signal"]
                cells.append([r["seed"], f["items"], f"{f['smooth_l1']:.4f}", _fmt(f["r2_over_mean"], 2),
                              _fmt(f["category_r2_over_mean"], 2), _fmt(f.get("identity_r2_over_mean"), 2),
                              _fmt(f.get("ridge_r2_over_mean"), 2), _fmt(f.get("offline_r2_over_mean"), 2),
                              _fmt(f["r2_over_category"], 2),
                              f"{g['signal_variance']:.3f} / {g['noise_variance']:.3f} ({g['signal_share']:.2f})"])  # fmt: skip
            md.append("f_w on held-out sub-goal items (odd items; the baselines fit on the even ones), R^2 over the "
                      "targets' mean: the online f_w; the target category's mean; s_0 itself (f_w's input); ridge "
                      "regression on [s_0 : g]; f_w's architecture trained offline on the even items (full batch, "
                      "Adam, early-stopped on a fifth of them); then f_w's R^2 over the category mean; i_tau's "
                      "variance: f_w's outputs across episodes / the noise's (signal share).\n")  # fmt: skip
            md.append(markdown_table(cells, ["seed", "items", "smooth-L1", "R^2 f_w", "category mean", "s_0",
                                             "ridge", "offline f_w", "R^2 f_w over category",
                                             "signal / noise variance"]) + "\n")  # fmt: skip
        if all(r["items"].get("fit_options") for r in per_seed):
            names = list(per_seed[0]["items"]["fit_options"])
            cells = [[r["seed"], *(_fmt(r["items"]["fit_options"][n], 2) for n in names),
                      _fmt(r["items"]["fit"]["offline_r2_over_mean"], 2)] for r in per_seed]  # fmt: skip
            md.append("f_w's online training replayed on the fit items at the trained encoder, from the run's initial "
                      "f_w, one option changed at a time (`--fit-options`): R^2 over the mean on the held-out items, "
                      "beside the offline f_w's.\n")  # fmt: skip
            md.append(markdown_table(cells, ["seed", *names, "offline f_w"]) + "\n")
        sub = [r["items"]["subgoal"] for r in per_seed]
        edges = sub[0]["edges"]
        bins = [f"{edges[i]:.1f}-{edges[i + 1]:.1f}" for i in range(len(edges) - 1)]
        cells = [[r["seed"], s["episodes"], *(_fmt(100 * x, 0) for x in s["shares"]), _fmt(100 * s["at_done"], 0)]
                 for r, s in zip(per_seed, sub)]  # fmt: skip
        md.append(f"Where the sub-goal falls in its successful episode ({windows} training windows): t*/T in % of "
                  "episodes, and t* = T (the Done step's own state).\n")  # fmt: skip
        md.append(markdown_table(cells, ["seed", "episodes", *[f"t*/T {b}" for b in bins], "at Done"]) + "\n")
    return "\n".join(md)


def probe(models: dict[str, list[Model]], episodes: int, windows: int, options_passes: int = 0) -> dict:
    """{method: [per seed: {"seed", "sr": `sr_conditions`, "items": `imagination_items`}]}."""
    from foresit_jax.evaluate import Evaluator
    from foresit_jax.probes import ShuffledImagination

    report, evaluators, t0 = {}, {}, time.time()
    for method, seeds in models.items():
        report[method] = []
        shuffled = ShuffledImagination(seeds[0].config)
        for model in seeds:
            where = Evaluator.scenes_of(model.config)
            evaluator = evaluators.setdefault(where, Evaluator(*where))
            sr = sr_conditions(model, evaluator, episodes, shuffled)
            items = imagination_items(model, windows, options_passes)
            report[method].append({"seed": model.seed, "sr": sr, "items": items})
            print(f"probe {method} seed {model.seed}: {sr} ({time.time() - t0:.0f} s)", flush=True)
    return report
