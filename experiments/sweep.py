"""Seed sweep: `python -m experiments.sweep --methods a3c a3c+foresit --seeds 5 --preset quick`.

Each method's seeds run vmapped inside one jitted program (in chunks, for progress).  The
protocol is `train`'s (experiments.selection): seed i of the sweep is seed `--seed + i`,
initialised from the key `train --seed <seed + i>` uses; after each chunk each seed is
validated on the episodes that run would validate on, and the model with the best
validation SR is the one tested, on that run's test episodes.  So a seed's numbers are
those of its `train` run, up to the float rounding of a vmapped program (the batched
matmuls differ in the last bits).  The last model is tested too, for comparison.

Written: the paper's Table 1 layout (SPL, SR, SPL>=5, SR>=5, mean +- std over seeds) of the
selected models as Markdown and CSV, the selected and last models' SR per seed, every
seed's results, validation history and training curve (JSON), and one learning-curve PNG of every method
(mean and band over seeds).
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
import tyro

from experiments import runs, selection
from experiments.presets import preset
from experiments.progress import progress_bar
from experiments.tables import markdown_table, write_csv

COLUMNS = ("SPL", "SR", "SPL>=5", "SR>=5")


@dataclasses.dataclass(frozen=True)
class Args:
    """Train several methods over several seeds and tabulate them as in Table 1."""

    methods: tuple[str, ...] = ("a3c", "a3c+foresit")
    """Methods to compare ('+'-joined pieces, see foresit_jax.methods)."""
    setup: str = "savn"
    """Environment setup: savn or org (the object-graph methods need org)."""
    seeds: int = 5
    """Seeds per method (vmapped in one program)."""
    preset: str = "quick"
    """Preset: tiny, quick or paper."""
    seed: int = 0
    """Base seed: seed i of a method is the run `train --seed <seed + i>` would make."""
    out: Path = Path("runs/sweep")
    """Output folder."""
    overwrite: bool = False
    """Replace an existing sweep in --out."""
    num_updates: Optional[int] = None
    """Override the preset's number of updates."""
    test_episodes_per_room: Optional[int] = None
    """Override the preset's test episodes per room type."""
    val_episodes_per_room: Optional[int] = None
    """Override the preset's validation episodes per room type."""
    progress: bool = True
    """Show the progress bar."""


def seeds_of(args: Args) -> list[int]:
    """The seeds of the sweep: those of `train --seed` for each of its runs."""
    return [args.seed + i for i in range(args.seeds)]


def method_schedule(method: str, args: Args):
    """The preset's Config and Schedule of `method`, with the sweep's overrides."""
    config, schedule = preset(args.preset, method, num_updates=args.num_updates, setup=args.setup)
    sched = {k: getattr(args, k) for k in ("test_episodes_per_room", "val_episodes_per_room")}
    return config, dataclasses.replace(schedule, **{k: v for k, v in sched.items() if v is not None})


def run_method(method: str, args: Args, bar, evaluator) -> tuple[list[dict], np.ndarray, np.ndarray]:
    """Train `args.seeds` seeds of one method vmapped, selecting each seed's model on
    validation after each chunk; returns (per seed: seed, selected update, test results of
    the selected and of the last model, validation history; updates [n]; training success
    rate [seeds, n]).  `evaluator` (a foresit_jax Evaluator of the sweep's setup) runs the
    validation and test episodes.  Each seed's training success rate per update is in
    its results too."""
    from foresit_jax.evaluate import agent_params
    from foresit_jax.train import make_trainer

    config, schedule = method_schedule(method, args)
    seeds = seeds_of(args)
    trainer = make_trainer(config)
    env_params = trainer.env_params
    states = jax.vmap(trainer.init)(jnp.stack([selection.run_key(s) for s in seeds]))
    run = jax.jit(jax.vmap(trainer.run, in_axes=(0, None, None)), static_argnums=2)
    best = [selection.Selection() for _ in seeds]
    history: list[list[dict]] = [[] for _ in seeds]
    curves, done = [], 0
    while done < config.num_updates:
        n = min(schedule.chunk_updates, config.num_updates - done)
        states, metrics = run(states, env_params, n)
        metrics = jax.tree.map(np.asarray, metrics)  # [seeds, n]
        loss = metrics["losses/total_loss"]
        if not np.isfinite(loss).all():
            seed, update = np.argwhere(~np.isfinite(loss))[0]
            runs.fail(f"{method}: non-finite loss at update {done + update + 1} of seed {seed}; sweep stopped", 1)
        curves.append(metrics["charts/success_rate"])
        done += n
        for i, seed in enumerate(seeds):  # model selection, as train does
            params = jax.device_get(agent_params(jax.tree.map(lambda x: x[i], states), config.sigma2_max))
            val = selection.validate(evaluator, params, config, seed, done, schedule.val_episodes_per_room)
            history[i].append({"update": done, **val["overall"]})
            best[i].offer(val["overall"]["SR"], done, params)
        val_sr = np.mean([h[-1]["SR"] for h in history])
        bar(n, {"method": method, "SR": f"{metrics['charts/success_rate'].mean():.3f}", "val SR": f"{val_sr:.1f}%"})
    curves = np.concatenate(curves, axis=1)
    results = []
    for i, seed in enumerate(seeds):
        last = agent_params(jax.tree.map(lambda x: x[i], states), config.sigma2_max)
        test = [evaluator.evaluate(p, config, "test", selection.test_key(seed), schedule.test_episodes_per_room)
                for p in (best[i].params, last)]  # fmt: skip
        results.append({"seed": seed, "selected_update": best[i].update, "selected": test[0], "last": test[1],
                        "validation": history[i], "training_success_rate": curves[i].tolist()})  # fmt: skip
    return results, np.arange(1, done + 1), curves


def table(results_by_method: dict[str, list[dict]], room: str = "overall") -> list[dict]:
    """Rows of Table 1: per method, mean and std over seeds of each column
    (`results_by_method`: per method, one test result per seed)."""
    rows = []
    for method, per_seed in results_by_method.items():
        row = {"method": method, "seeds": len(per_seed)}
        for col in COLUMNS:
            values = np.array([r[room][col] for r in per_seed], float)
            row[f"{col} mean"] = float(np.nanmean(values))
            row[f"{col} std"] = float(np.nanstd(values))
        rows.append(row)
    return rows


def table_markdown(rows: list[dict], title: str) -> str:
    cells = [[row["method"], *(f"{row[f'{c} mean']:.2f} ± {row[f'{c} std']:.2f}" for c in COLUMNS)] for row in rows]
    return f"# {title}\n\n" + markdown_table(cells, ["Method", *COLUMNS]) + "\n"


def selection_markdown(results: dict[str, list[dict]]) -> str:
    """Test SR of the model selected on validation against the last model, per method
    (mean ± std over seeds) and per seed."""
    cells = []
    for method, per_seed in results.items():
        sr = {k: np.array([r[k]["overall"]["SR"] for r in per_seed], float) for k in ("selected", "last")}
        seeds = ", ".join(f"{r['seed']}: {r['selected']['overall']['SR']:.1f} / {r['last']['overall']['SR']:.1f}"
                          f" (update {r['selected_update']})" for r in per_seed)  # fmt: skip
        cells.append([method, *(f"{v.mean():.2f} ± {v.std():.2f}" for v in sr.values()), seeds])
    header = ["Method", "SR, selected", "SR, last", "per seed: selected / last (selected update)"]
    return "## Model selection: the model of the best validation SR against the last one, test split\n\n" + (
        markdown_table(cells, header) + "\n")


def main(args: Args) -> list[dict]:
    from foresit_jax.evaluate import Evaluator

    if args.seeds < 1:
        raise runs.UserError(f"--seeds must be >= 1, got {args.seeds}")
    if not args.methods:
        raise runs.UserError("--methods needs at least one method")
    for name in ("test_episodes_per_room", "val_episodes_per_room"):
        if getattr(args, name) is not None and getattr(args, name) < 1:
            raise runs.UserError(f"--{name.replace('_', '-')} must be >= 1, got {getattr(args, name)}")
    for method in args.methods:  # fail before any training
        method_schedule(method, args)
    out = args.out
    runs.prepare_run_dir(out, resume=False, overwrite=args.overwrite, marker="sweep.json", kind="sweep")
    runs.write_json(out / "sweep.json", args)

    config, _ = preset(args.preset, args.methods[0], num_updates=args.num_updates, setup=args.setup)
    evaluator = Evaluator(args.setup)  # one for the sweep: each method's evaluation compiles once
    bar = progress_bar(config.num_updates * len(args.methods), 0, args.progress)
    t0 = time.time()
    results, curves = {}, {}
    for method in args.methods:
        results[method], x, y = run_method(method, args, bar, evaluator)
        curves[method] = (x, runs.smooth(y))
    bar(0, None)
    rows = table({method: [r["selected"] for r in per_seed] for method, per_seed in results.items()})
    title = (f"Table 1 layout: test split, preset {args.preset}, seeds {args.seed}-{args.seed + args.seeds - 1} "
             "(mean ± std; each seed's model selected on validation)")  # fmt: skip
    md = table_markdown(rows, title) + "\n" + selection_markdown(results)
    (out / "table1.md").write_text(md)
    write_csv(out / "table1.csv", rows)
    runs.write_json(out / "results_per_seed.json", results)
    runs.learning_curve_png(out / "learning_curves.png", curves)
    print(md)
    print(f"wrote {out}/table1.md, table1.csv, results_per_seed.json, learning_curves.png ({time.time() - t0:.0f} s)")
    return rows


def cli(argv=None) -> None:
    args = tyro.cli(Args, args=argv)
    try:
        main(args)
    except (runs.UserError, ValueError) as e:
        runs.fail(str(e))


if __name__ == "__main__":
    cli(sys.argv[1:])
