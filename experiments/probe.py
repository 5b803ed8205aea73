"""Probe a trained agent's imagination: `python -m experiments.probe --run runs/quick`.

`--run` is a run folder of `experiments.train` or a sweep folder of `experiments.sweep`
(every finished method with imagination or the attention critic, or `--methods`; every
seed). For each seed's selected model (`foresit_jax.probes` has the functions):

* test SR on the same test episodes (the run's test key, `--episodes-per-room` per room
  type) with i_tau as the default evaluation gives it (the trained f_w, the noise at the
  end of training, whatever `Config.evaluation_noise` the run used), with the noise off, from an untrained f_w (the run's initial w),
  shuffled across episodes, and shuffled with the noise off (only i_tau's content moves); for a method evaluated greedily (ORG), also with sampled
  actions. Each condition is paired with the first over the seeds (`experiments.stats`);
* f_w against its targets on `--windows` fresh training windows of the agent (held out:
  f_w never trained on them): smooth-L1, R^2 over the targets' mean, and over each target
  category's mean; what f_w's inputs tell, fit on half the items: s_0 itself, ridge on
  [s_0 : g], f_w's architecture trained offline (`foresit_jax.probes.imagination_fit`);
  the variance of f_w's outputs beside the noise's;
* where the sub-goal falls in its successful episode: t*/T and the share at the Done step.

Writes `probe.md` and `probe.json` into `--run` or `--out` (refusing to replace them without
`--overwrite`) and prints the Markdown.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path
from typing import Optional

import jax
import jax.numpy as jnp
import numpy as np

from experiments import runs, selection, stats
from experiments.tables import markdown_table

CONDITIONS = ("trained", "noise off", "untrained f_w", "shuffled", "shuffled, noise off", "sampled actions")


@dataclasses.dataclass(frozen=True)
class Args:
    """Probe whether a trained agent uses its imagination, and what f_w learned."""

    run: Path
    """A run folder (experiments.train) or a sweep folder (experiments.sweep)."""
    methods: tuple[str, ...] = ()
    """For a sweep: the methods to probe (default: every finished one with imagination or
    the attention critic)."""
    episodes_per_room: int = 100
    """Test episodes per room type for each condition."""
    windows: int = 40
    """Training windows played to collect f_w's held-out items and the sub-goals."""
    fit_options: bool = False
    """Also replay f_w's online training with other options (`FIT_OPTIONS`) on the same
    items at the trained encoder, from the run's initial f_w, streamed --fit-passes times:
    which procedure fits as well as the offline f_w."""
    fit_passes: int = 5
    """How many times the items are streamed through each replayed option."""
    out: Optional[Path] = None
    """Folder for probe.md and probe.json (default: --run)."""
    overwrite: bool = False
    """Replace an existing probe.md / probe.json."""


# f_w's training options replayed by --fit-options: the run's own first, then one change
# each (Config fields: imagination_optimizer, imagination_lr, imagination_epochs, buffer_size,
# imagination_batch).
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
}


@dataclasses.dataclass
class Model:
    """One seed's model to probe."""

    config: object
    trainer: object
    seed: int
    state: object  # the training RunnerState, with the selected model's params and w
    selected: object  # AgentParams of the selected model


def models_of_run(run: Path) -> dict[str, list[Model]]:
    """{method: [Model]} of a train run folder."""
    from foresit_jax.config import Config
    from foresit_jax.evaluate import agent_params
    from foresit_jax.train import make_trainer

    info = runs.read_run_info(run)
    config = Config(**info["config"])
    trainer = make_trainer(config)
    like = trainer.init(selection.run_key(info["seed"]))
    steps = [runs.checkpoint_manager(run / name, 100).latest_step() for name in ("checkpoints", "best")]
    if None in steps:
        raise runs.UserError(f"{run} has no finished checkpoint (checkpoints/ and best/); train it to the end first")
    state = runs.restore(runs.checkpoint_manager(run / "checkpoints", 100), steps[0], like)
    selected = runs.restore(runs.checkpoint_manager(run / "best", 100), steps[1],
                            agent_params(like, config.sigma2_max, config.evaluation_noise))  # fmt: skip
    state = state._replace(params=selected.params, imagination_params=selected.imagination_params)
    return {config.method: [Model(config, trainer, info["seed"], state, selected)]}


def models_of_sweep(folder: Path, methods: tuple[str, ...]) -> dict[str, list[Model]]:
    """{method: [Model per seed]} of a sweep's finished methods."""
    from experiments import sweep

    saved = runs.read_json(folder / "sweep.json")
    args = runs.args_from_saved(sweep.Args, saved, out=folder)
    finished = [m for m in args.methods if sweep.finished_seeds(folder / "methods" / m)]
    unknown = [m for m in methods if m not in finished]
    if unknown:
        raise runs.UserError(f"{folder} has no finished {', '.join(unknown)}; finished: {', '.join(finished) or 'none'}")
    out = {}
    for method in methods or finished:
        config, _ = sweep.method_schedule(method, args)
        if not methods and not (config.pieces.imagination.uses_imagination or config.pieces.attention_critic):
            continue
        config, trainer, states, best = sweep.load_method(method, args, folder / "methods" / method)
        seeds = sweep.finished_seeds(folder / "methods" / method)
        out[method] = []
        for i, seed in enumerate(seeds):
            state, selected = jax.tree.map(lambda x: x[i], (states, best))
            state = state._replace(params=selected.params, imagination_params=selected.imagination_params)
            out[method].append(Model(config, trainer, seed, state, selected))
    return out


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
    if config.pieces.imagination.uses_imagination:
        out["noise off"] = sr(trained._replace(noise_variance=jnp.zeros_like(training_end)))
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
        try:
            config = dataclasses.replace(model.config, **change)
        except ValueError:  # e.g. a batch that does not divide this run's buffer: not applicable
            out[name] = float("nan")
            continue
        optimizer = make_imagination_optimizer(config.imagination_optimizer, config.imagination_lr)
        w = replay_online_fit(model.trainer.agent.imagine, w_init, s_0, goal, subgoal, only_fit_items(add), optimizer,
                              config.imagination_epochs, config.buffer_size, passes, config.imagination_batch)  # fmt: skip
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
    if model.config.pieces.imagination.trains_imagination and add.sum() >= 4:
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


def main(args: Args) -> dict:

    if args.episodes_per_room < 1 or args.windows < 1 or args.fit_passes < 1:
        raise runs.UserError("--episodes-per-room, --windows and --fit-passes must be >= 1")
    folder = args.run if args.out is None else args.out
    out_md, out_json = folder / "probe.md", folder / "probe.json"
    if out_json.exists() and not args.overwrite:
        raise runs.UserError(f"{out_json} exists; pass --overwrite to replace it")
    t0 = time.time()
    if (args.run / "sweep.json").is_file():
        models = models_of_sweep(args.run, args.methods)
    else:
        if args.methods:
            raise runs.UserError("--methods is for a sweep folder; a run folder holds one method")
        models = models_of_run(args.run)
    if not models:
        raise runs.UserError(f"{args.run}: no finished method with imagination or the attention critic to probe")
    runs.claim(folder)  # the one writer of the folder, and writable, before the probe's work
    report = probe(models, args.episodes_per_room, args.windows, args.fit_passes if args.fit_options else 0)
    md = markdown(report, args.episodes_per_room, args.windows)
    folder.mkdir(parents=True, exist_ok=True)
    runs.write_json(out_json, {"episodes_per_room": args.episodes_per_room, "windows": args.windows,
                               "fit_passes": args.fit_passes if args.fit_options else 0, "methods": report})  # fmt: skip
    out_md.write_text(md)
    print(md)
    print(f"wrote {out_md} and {out_json} ({time.time() - t0:.0f} s)")
    return report


def cli(argv=None) -> None:
    runs.run_cli(Args, main, argv)


if __name__ == "__main__":
    cli(sys.argv[1:])
