"""Does a grid of learning rates pay as one program? (`foresit_jax.train.GridTrainer`)

    python -m benchmarks.bench_grid --rates 3e-4 1e-3 --seeds 5 --preset quick

Times, in one run and in turns, the two ways to train every seed at every rate:
* `arms`: what `experiments.tune` does: each rate its own sweep, the seeds vmapped
  (`Trainer.run_seeds`), one rate after the other;
* `grid`: every (rate, seed) pair vmapped in one program (`GridTrainer`).
One jitted chunk of `--updates` updates each; the best of `--repeats` calls after a
warm-up (the compile is reported apart). One table: seconds per chunk for the whole grid,
useful frames/s over all of it, and grid / arms.
"""

from __future__ import annotations

import dataclasses
import time

import tyro


@dataclasses.dataclass(frozen=True)
class BenchGrid:
    rates: tuple[float, ...] = (3e-4, 1e-3)
    """learning rates of the grid"""
    seeds: int = 5
    """seeds at every rate"""
    method: str = "a3c+foresit"
    """method to train"""
    preset: str = "quick"
    """preset giving the sizes"""
    updates: int = 20
    """updates per timed call"""
    repeats: int = 3
    """timed rounds (each times both ways, in turns; the best is reported)"""


def main(bench: BenchGrid) -> dict:
    import jax
    import jax.numpy as jnp
    import numpy as np

    from experiments.running.presets import preset
    from foresit_jax.train import GridTrainer, Trainer, grid_inputs

    for name in ("seeds", "updates", "repeats"):
        if getattr(bench, name) < 1:
            raise ValueError(f"--{name} must be at least 1, got {getattr(bench, name)}")
    if not bench.rates or any(not r > 0 for r in bench.rates):
        raise ValueError(f"--rates: give at least one positive learning rate, got {list(bench.rates)}")
    config, _ = preset(bench.preset, bench.method, num_updates=bench.updates)
    seeds = range(bench.seeds)
    grid = GridTrainer(config)
    keys, rates = grid_inputs(seeds, bench.rates)
    grid_states = jax.jit(jax.vmap(grid.init))(keys, rates)
    arms = [Trainer(dataclasses.replace(config, learning_rate=r), grid.env, grid.env_params) for r in bench.rates]
    arm_states = [jax.jit(jax.vmap(t.init))(keys[: bench.seeds]) for t in arms]

    def run_grid():
        return jax.block_until_ready(grid.run_seeds(grid_states, grid.env_params, bench.updates))[1]

    def run_arms():
        return [jax.block_until_ready(t.run_seeds(s, t.env_params, bench.updates))[1] for t, s in zip(arms, arm_states)]

    timed = {"arms": [], "grid": []}
    compile_s = {}
    for name, fn in (("arms", run_arms), ("grid", run_grid)):
        start = time.perf_counter()
        fn()
        compile_s[name] = time.perf_counter() - start
    frames = None
    for _ in range(bench.repeats):  # in turns: the machine's drift falls on both
        for name, fn in (("arms", run_arms), ("grid", run_grid)):
            start = time.perf_counter()
            metrics = fn()
            timed[name].append(time.perf_counter() - start)
            if name == "grid":
                frames = float(np.sum(np.asarray(metrics["frames/useful"])))
    best = {k: min(v) for k, v in timed.items()}
    print(
        f"{bench.method}, preset {bench.preset}: {len(bench.rates)} rates x {bench.seeds} seeds, "
        f"{bench.updates} updates per chunk, best of {bench.repeats} ({jax.devices()[0].device_kind})"
    )
    print("| way | s per chunk (whole grid) | useful frames/s | compile + first call s |")
    print("|---|---|---|---|")
    for name in ("arms", "grid"):
        print(f"| {name} | {best[name]:.2f} | {frames / best[name]:,.0f} | {compile_s[name]:.1f} |")
    print(f"grid / arms speed: {best['arms'] / best['grid']:.2f}x")
    return {
        "best_s": best,
        "compile_s": compile_s,
        "useful_frames": frames,
        "speedup": best["arms"] / best["grid"],
        "rates": np.asarray(jnp.asarray(rates)).tolist(),
    }


if __name__ == "__main__":
    main(tyro.cli(BenchGrid))
