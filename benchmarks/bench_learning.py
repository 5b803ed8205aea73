"""Time to a success rate: wall time and useful frames until the training success rate
(episodes that ended in the last `--chunk` updates, all four room types) first reaches
10, 20 and 30 %, per method, each seed run alone (so wall times are a single run's).

    python -m benchmarks.bench_learning --methods a3c a3c+foresit --seeds 3 --frames 2000000

Prints one line per run as it finishes, then a table: for each method and goal, how many
seeds reached it, and the mean ± std (over the seeds that did) of the wall seconds
(compilation excluded; it is printed apart) and of the useful frames.
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import tyro

from benchmarks.search_learner import GOALS, Args, run_variant


@dataclasses.dataclass(frozen=True)
class BenchLearning:
    methods: tuple[str, ...] = ("a3c", "a3c+foresit")
    """methods to measure (the quick preset's learner)"""
    seeds: int = 3
    """seeds per method, run one after another (seed i uses PRNGKey(i), as train --seed i)"""
    frames: int = 2_000_000
    """useful frames per run"""
    chunk: int = 50
    """updates between two measurements of the training success rate"""
    preset: str = "quick"
    """preset whose config is measured"""


def mean_std(values) -> str:
    return f"{np.mean(values):,.0f} ± {np.std(values):,.0f}" if values else "-"


def main(bench: BenchLearning) -> dict:
    results = {}
    for method in bench.methods:
        runs = []
        for seed in range(bench.seeds):
            args = Args(base_preset=bench.preset, method=method, seeds=1, frames=bench.frames, chunk=bench.chunk)
            run = run_variant(args, {}, keys=jax.random.PRNGKey(seed)[None])
            print(
                f"{method} seed {seed}: compile {run['compile_s']} s, reached {run['reached']}, "
                f"final SR {run['final_sr_mean']}% after {run['seconds']} s / {run['frames']:,} frames",
                flush=True,
            )
            runs.append(run)
        results[method] = runs
    print()
    print("| method | goal (training SR) | seeds reaching it | wall s to it | useful frames to it |")
    print("|---|---|---|---|---|")
    for method, runs in results.items():
        for goal in GOALS:
            hits = [r["reached"][str(goal)] for r in runs if str(goal) in r["reached"]]
            print(
                f"| {method} | {100 * goal:.0f}% | {len(hits)}/{len(runs)} | {mean_std([h[0] for h in hits])} | "
                f"{mean_std([h[1] for h in hits])} |"
            )
    return results


if __name__ == "__main__":
    main(tyro.cli(BenchLearning))
