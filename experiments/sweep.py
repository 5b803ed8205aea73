"""Seed sweep: `python -m experiments.sweep --methods a3c a3c+foresit --seeds 5 --preset quick`.

Each method's seeds run vmapped inside one jitted program (in chunks, for progress).  Each
seed's final agent is evaluated on the test split; the paper's Table 1 layout (SPL, SR,
SPL>=5, SR>=5, mean +- std over seeds) is written as Markdown and CSV, with one
learning-curve PNG of every method (mean and band over seeds).
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path
from typing import Optional

import jax
import numpy as np
import tyro

from experiments import runs
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
    """Base seed; seed i of a method uses fold_in(PRNGKey(seed), i)."""
    out: Path = Path("runs/sweep")
    """Output folder."""
    overwrite: bool = False
    """Replace an existing sweep in --out."""
    num_updates: Optional[int] = None
    """Override the preset's number of updates."""
    test_episodes_per_room: Optional[int] = None
    """Override the preset's test episodes per room type."""
    progress: bool = True
    """Show the progress bar."""


def seed_keys(seed: int, seeds: int) -> jax.Array:
    return jax.vmap(lambda i: jax.random.fold_in(jax.random.PRNGKey(seed), i))(np.arange(seeds))


def run_method(method: str, args: Args, bar, evaluator) -> tuple[list[dict], np.ndarray, np.ndarray]:
    """Train `args.seeds` seeds of one method vmapped; returns (per-seed test results,
    updates [n], training success rate [seeds, n]); `evaluator` (a foresit_jax Evaluator of
    the sweep's setup) runs the test episodes."""
    from foresit_jax.evaluate import agent_params
    from foresit_jax.train import make_trainer

    config, schedule = preset(args.preset, method, num_updates=args.num_updates, setup=args.setup)
    trainer = make_trainer(config)
    env_params = trainer.env_params
    states = jax.vmap(trainer.init)(seed_keys(args.seed, args.seeds))
    run = jax.jit(jax.vmap(trainer.run, in_axes=(0, None, None)), static_argnums=2)
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
        bar(n, {"method": method, "SR": f"{metrics['charts/success_rate'].mean():.3f}"})
    episodes = schedule.test_episodes_per_room if args.test_episodes_per_room is None else args.test_episodes_per_room
    results = []
    for i in range(args.seeds):
        state_i = jax.tree.map(lambda x: x[i], states)
        key = jax.random.fold_in(jax.random.PRNGKey(args.seed + 10_000), i)
        results.append(evaluator.evaluate(agent_params(state_i, config.sigma2_max), config, "test", key, episodes))
    return results, np.arange(1, done + 1), np.concatenate(curves, axis=1)


def table(results_by_method: dict[str, list[dict]], room: str = "overall") -> list[dict]:
    """Rows of Table 1: per method, mean and std over seeds of each column."""
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


def main(args: Args) -> list[dict]:
    from foresit_jax.evaluate import Evaluator

    if args.seeds < 1:
        raise runs.UserError(f"--seeds must be >= 1, got {args.seeds}")
    if not args.methods:
        raise runs.UserError("--methods needs at least one method")
    if args.test_episodes_per_room is not None and args.test_episodes_per_room < 1:
        raise runs.UserError(f"--test-episodes-per-room must be >= 1, got {args.test_episodes_per_room}")
    for method in args.methods:  # fail before any training
        preset(args.preset, method, num_updates=args.num_updates, setup=args.setup)
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
    rows = table(results)
    title = f"Table 1 layout: test split, preset {args.preset}, {args.seeds} seeds (mean ± std)"
    md = table_markdown(rows, title)
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
    except (runs.UserError, ValueError, NotImplementedError) as e:
        runs.fail(str(e))


if __name__ == "__main__":
    cli(sys.argv[1:])
