"""Is a seed sweep faster with its seeds spread over several host devices?

    python -m benchmarks.bench_devices --seeds 4 --preset quick --devices 1 2

For each device count N a fresh interpreter (XLA_FLAGS=--xla_force_host_platform_device_count=N
must be set before jax starts) times the program `experiments.sweep` runs: `--seeds` seeds
of a method vmapped, the seed axis sharded over the N devices (experiments.running.devices), one
jitted chunk of `--updates` updates, best of `--repeats` calls after a warm-up. One table,
measured in one run: seconds per chunk, useful frames/s over all seeds, and the speed
relative to the first device count.
"""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import tyro


@dataclasses.dataclass(frozen=True)
class BenchDevices:
    devices: tuple[int, ...] = (1, 2)
    """host device counts to compare"""
    seeds: int = 4
    """seeds in the vmapped program"""
    method: str = "a3c+foresit"
    """method to train"""
    preset: str = "quick"
    """preset giving the sizes"""
    updates: int = 20
    """updates per timed call"""
    repeats: int = 3
    """timed calls (the best is reported)"""


def measure(bench: BenchDevices) -> dict:
    """In this process: time the sharded, vmapped chunk on all local devices."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from experiments.running import devices, selection
    from experiments.running.presets import preset
    from foresit_jax.train import make_trainer

    config, _ = preset(bench.preset, bench.method, num_updates=bench.updates)
    trainer = make_trainer(config)
    mesh = devices.seed_mesh(bench.seeds)
    keys = jnp.stack([selection.run_key(s) for s in range(bench.seeds)])
    states = devices.shard_seeds(jax.vmap(trainer.init)(keys), mesh)
    run = trainer.run_seeds
    start = time.perf_counter()
    states, _ = jax.block_until_ready(run(states, trainer.env_params, bench.updates))  # compile + warm-up
    compile_s = time.perf_counter() - start
    times, useful = [], 0.0
    for _ in range(bench.repeats):
        start = time.perf_counter()
        states, metrics = jax.block_until_ready(run(states, trainer.env_params, bench.updates))
        times.append(time.perf_counter() - start)
        useful = float(np.sum(metrics["frames/useful"]))
    return {
        "devices": int(mesh.devices.size),
        "local_devices": jax.device_count(),
        "compile_s": compile_s,
        "best_s": min(times),
        "useful_fps": useful / min(times),
    }


def main(bench: BenchDevices) -> list[dict]:
    rows = []
    for n in bench.devices:
        env = {
            **os.environ,
            "XLA_FLAGS": f"{os.environ.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count={n}",
        }
        code = (
            "import json, tyro; from benchmarks import bench_devices as B; "
            "print('RESULT', json.dumps(B.measure(tyro.cli(B.BenchDevices))))"
        )
        argv = [
            f"--seeds={bench.seeds}",
            f"--method={bench.method}",
            f"--preset={bench.preset}",
            f"--updates={bench.updates}",
            f"--repeats={bench.repeats}",
        ]
        proc = subprocess.run(
            [sys.executable, "-c", code, *argv],
            env=env,
            capture_output=True,
            text=True,
            cwd=Path(__file__).resolve().parents[1],
        )  # the root, where `benchmarks` imports from
        if proc.returncode != 0:
            raise SystemExit(f"error: the run with {n} host devices failed:\n{proc.stderr[-2000:]}")
        row = json.loads(proc.stdout.split("RESULT", 1)[1])
        rows.append(row)
        print(
            f"{n} host device(s): {row['devices']} used, compile {row['compile_s']:.1f} s, "
            f"{row['best_s']:.2f} s per {bench.updates} updates, {row['useful_fps']:,.0f} useful frames/s",
            flush=True,
        )
    print(f"\n{bench.method}, preset {bench.preset}, {bench.seeds} seeds vmapped, {bench.updates} updates per call\n")
    print("| host devices | used | compile s | s per call | useful frames/s (all seeds) | speed vs first |")
    print("|---|---|---|---|---|---|")
    for row in rows:
        print(
            f"| {row['local_devices']} | {row['devices']} | {row['compile_s']:.1f} | {row['best_s']:.2f} | "
            f"{row['useful_fps']:,.0f} | {rows[0]['best_s'] / row['best_s']:.2f}x |"
        )
    return rows


if __name__ == "__main__":
    main(tyro.cli(BenchDevices))
