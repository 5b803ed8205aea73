"""The learner's hyperparameter search: training success rate against useful frames and
wall time, on all four room types, for variants of one base config.

    python -m benchmarks.search_learner --variants '{}' '{"learning_rate": 3e-4}' \
        --seeds 2 --frames 1500000 --out search.jsonl

Each variant is a JSON dict of `Config` fields over `BASE` (the `quick` preset's learner).
Its seeds run vmapped in one program for a fixed number of useful frames per seed;
every `--chunk` updates the host records the mean training success rate (episodes that
ended in those updates) per seed. One JSON line per variant goes to stdout (and `--out`):
the curve, the frames and seconds at which the mean over seeds first reached 10, 20 and
30 %, and the final rate per seed. Seconds here are those of the vmapped seeds together;
frames are per seed (divide frames by one seed's frames/s from `bench_train` for the wall
time of a single run). The table in docs/learner.md was made with this script.
"""

from __future__ import annotations

import dataclasses
import json
import time

import jax
import numpy as np
import tyro

from experiments.running.presets import PRESETS
from foresit_jax.config import Config
from foresit_jax.train import Trainer

GOALS = (0.1, 0.2, 0.3)


@dataclasses.dataclass(frozen=True)
class Args:
    variants: tuple[str, ...] = ("{}",)
    """variants as JSON dicts of Config fields, over the quick preset's config"""
    base_preset: str = "quick"
    """preset whose Config fields are the base of every variant"""
    method: str = "a3c+foresit"
    """method of the base config"""
    seeds: int = 2
    """seeds per variant (vmapped in one program)"""
    frames: int = 1_500_000
    """useful frames per seed per variant"""
    chunk: int = 50
    """updates per jitted chunk (one point of the curve)"""
    out: str = ""
    """optional JSONL file to append results to"""


def base_config(args: Args, overrides: dict) -> Config:
    fields, _ = PRESETS[args.base_preset]
    fields = {k: v for k, v in fields.items() if k != "num_updates"}
    return Config(method=args.method, **{**fields, **overrides})


def run_variant(args: Args, overrides: dict, keys=None) -> dict:
    """Train one variant (seeds vmapped) for `args.frames` useful frames per seed.
    keys: the seeds' PRNG keys `[S, 2]` (default: `args.seeds` keys split from key 0)."""
    config = base_config(args, overrides)
    trainer = Trainer(config)
    keys = jax.random.split(jax.random.PRNGKey(0), args.seeds) if keys is None else keys
    start = time.perf_counter()
    init = jax.jit(jax.vmap(trainer.init))
    run = jax.jit(jax.vmap(lambda s: trainer.run(s, trainer.env_params, args.chunk)))
    state = jax.block_until_ready(init(keys))
    state, _ = jax.block_until_ready(run(state))  # compile (and one chunk, not counted)
    compile_s = time.perf_counter() - start
    curve, frames, reached = [], 0.0, {}
    start = time.perf_counter()
    while frames < args.frames:
        state, metrics = run(state)
        success = np.asarray(metrics["charts/success_rate"]).mean(1)  # [S]
        frames += float(np.asarray(metrics["frames/useful"]).sum(1).mean())
        elapsed = time.perf_counter() - start
        mean = float(success.mean())
        curve.append(
            [round(elapsed, 1), int(frames), round(100 * mean, 1), [round(100 * float(x), 1) for x in success]]
        )
        for goal in GOALS:
            if str(goal) not in reached and mean >= goal:
                reached[str(goal)] = [round(elapsed, 1), int(frames)]
    last = curve[-max(1, len(curve) // 10) :]  # the last tenth of the run
    final = np.mean([c[3] for c in last], axis=0)
    return {
        "overrides": overrides,
        "seeds": int(keys.shape[0]),
        "compile_s": round(compile_s, 1),
        "seconds": curve[-1][0],
        "frames": int(frames),
        "reached": reached,
        "final_sr_mean": round(float(final.mean()), 1),
        "final_sr_per_seed": [round(float(x), 1) for x in final],
        "curve": curve,
    }


def main(args: Args) -> list[dict]:
    variants = []
    for i, text in enumerate(args.variants):  # every variant parsed before any trains
        try:
            variants.append(json.loads(text))
        except json.JSONDecodeError as e:
            raise SystemExit(f"error: --variants item {i + 1} ({text!r}) is not a JSON object: {e}") from None
        if not isinstance(variants[-1], dict):
            raise SystemExit(f"error: --variants item {i + 1} ({text!r}) is not a JSON object of Config fields")
    results = []
    for overrides in variants:
        result = run_variant(args, overrides)
        summary = {k: v for k, v in result.items() if k != "curve"}
        print(json.dumps(summary), flush=True)
        if args.out:
            with open(args.out, "a") as f:
                f.write(json.dumps(result) + "\n")
        results.append(result)
    return results


if __name__ == "__main__":
    main(tyro.cli(Args))
