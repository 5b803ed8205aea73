"""Training throughput: frames/s (useful and stepped), updates/s, compile time, memory and
the environment's share of the time, for methods and learner layouts side by side.

    python -m benchmarks.bench_train --preset quick --methods a3c a3c+foresit \
        --rollouts packed episodes --gradients replay through_rollout --lanes 32
    python -m benchmarks.bench_train --methods a3c a3c+maml --rollouts episodes \
        --gradients through_rollout --variants '{}' '{"maml_first_order": true}'

For every combination, one jitted `Trainer.run` of `--updates` updates is compiled, run
once, then timed `--repeats` times from the same state (so every repeat does the same
work), the programs taking turns so that they share whatever else the machine is doing.
Columns:

* useful frames/s: steps that enter the loss per second (what learning gets);
* stepped frames/s: environment steps per second, padding included (whole-episode
  updates step their lanes to `num_steps` after the episode ended and mask the rest);
* useful %: their ratio, from the run's own `frames/useful` metric;
* updates/s, compile s (lower + compile of the timed program), temp MB (XLA's temporary
  buffers of the program, where the backend reports them);
* env %: the environment alone (same lanes and steps, random actions) over the update;
* x first: best time per useful frame relative to the table's first row.

Everything is measured through public functions (`Trainer.init`, `Trainer.run`, the
environment's `reset`/`step`). Early in training (as here: a near-uniform policy ends
episodes fast) whole-episode updates are mostly padding; later, less.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import statistics
import sys
import time

import jax
import jax.numpy as jnp
import numpy as np
import tyro

from envs.gridnav import TRAIN_TIME_LIMIT
from experiments import errors
from experiments.running.presets import preset
from foresit_jax.methods import parse_method
from foresit_jax.train import Trainer


@dataclasses.dataclass(frozen=True)
class BenchConfig:
    """Training throughput of methods and learner layouts at a preset's sizes."""

    methods: tuple[str, ...] = ("a3c", "a3c+foresit")
    """methods to compare (see foresit_jax.methods)"""
    preset: str = "quick"
    """preset giving the network sizes and the window length"""
    setup: str = "savn"
    """environment setup: savn, or org (needed by the object-graph methods, e.g. a3c+org)"""
    lanes: tuple[int, ...] = (32,)
    """numbers of env lanes (A3C agents) per update"""
    rollouts: tuple[str, ...] = ("packed",)
    """learner layouts: packed (windows, lanes never idle) and/or episodes (whole, padded)"""
    gradients: tuple[str, ...] = ("replay",)
    """gradient paths: replay and/or through_rollout"""
    num_steps: int = 0
    """window length T for packed rollouts (0: the preset's); whole episodes use the time limit"""
    updates: int = 20
    """updates per timed call (the length of the jitted scan)"""
    repeats: int = 3
    """timed calls per program (best and median are reported)"""
    seed: int = 0
    """PRNG seed"""
    variants: tuple[str, ...] = ("{}",)
    """Config overrides as JSON, one row each per combination, e.g. '{}' '{"maml_first_order": true}'
    '{"maml_inner_updates": 0}' (where a maml update's time goes; maml_* fields apply to maml methods only)"""


@dataclasses.dataclass(frozen=True)
class Measurement:
    label: str
    lanes: int
    num_steps: int
    updates: int
    compile_s: float
    best_s: float
    median_s: float
    useful_frames: float  # per timed call
    stepped_frames: int  # per timed call
    temp_mb: float | None
    env_s: float

    @property
    def useful_fps(self) -> float:
        return self.useful_frames / self.best_s

    @property
    def stepped_fps(self) -> float:
        return self.stepped_frames / self.best_s


def timed(fn) -> float:
    start = time.perf_counter()
    jax.block_until_ready(fn())
    return time.perf_counter() - start


def env_only(trainer: Trainer, num_windows: int):
    """Compiled `key -> scalar`: `num_windows` windows of the environment alone, random actions."""
    env, lanes, steps = trainer.env, trainer.config.num_lanes, trainer.config.num_steps
    vstep = jax.vmap(env.step, in_axes=(0, 0, 0, None))

    def window(env_params, key):
        k_reset, k_steps = jax.random.split(key)
        obs, state = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(k_reset, lanes), env_params)

        def step(carry, key):
            obs, state = carry
            k_act, k_env = jax.random.split(key)
            action = jax.random.randint(k_act, (lanes,), 0, env.num_actions)
            obs, state, reward, *_ = vstep(jax.random.split(k_env, lanes), state, action, env_params)
            return (obs, state), reward

        (obs, _), rewards = jax.lax.scan(step, (obs, state), jax.random.split(k_steps, steps))
        return jnp.sum(rewards) + jnp.sum(obs["view"])  # keeps every step live

    def run(env_params, key):
        return jnp.sum(jax.lax.map(lambda k: window(env_params, k), jax.random.split(key, num_windows)))

    return jax.jit(run).lower(trainer.env_params, jax.random.key(0)).compile()


def temp_megabytes(compiled) -> float | None:
    try:
        analysis = compiled.memory_analysis()
        return analysis.temp_size_in_bytes / 2**20 if analysis is not None else None
    except Exception:  # not every backend reports it
        return None


def parse_variant(variant: str) -> dict:
    """One --variants entry: a JSON object of Config fields."""
    try:
        extra = json.loads(variant)
    except json.JSONDecodeError as e:
        raise ValueError(f"--variants entries must be JSON objects of Config fields, got {variant!r} ({e})") from None
    if not isinstance(extra, dict):
        raise ValueError(f"--variants entries must be JSON objects of Config fields, e.g. '{{}}', got {variant!r}")
    return extra


def combinations(bench: BenchConfig):
    """(label, Config) of every combination; a method that supports only some layouts or
    gradient paths (maml: whole episodes through the rollout) runs with its own, once."""
    seen = set()
    for method, rollout, gradient, lanes, variant in itertools.product(
        bench.methods, bench.rollouts, bench.gradients, bench.lanes, bench.variants
    ):
        pieces = parse_method(method)
        rollout = rollout if rollout in pieces.rollouts else pieces.rollouts[0]
        gradient = gradient if gradient in pieces.gradients else pieces.gradients[0]
        extra = parse_variant(variant)
        if not pieces.base_piece.adapts_in_episode:  # the maml_* fields change only an adapting base: one row
            extra = {k: v for k, v in extra.items() if not k.startswith("maml_")}
        label = f"{method} {rollout} {gradient}" + (f" {variant}" if extra else "")
        if (label, lanes) in seen:
            continue
        seen.add((label, lanes))
        overrides = dict(
            num_lanes=lanes, num_updates=bench.updates, rollout=rollout, gradient=gradient, setup=bench.setup
        )
        if rollout == "episodes":
            overrides["num_steps"] = TRAIN_TIME_LIMIT  # one whole episode per lane
        elif bench.num_steps:
            overrides["num_steps"] = bench.num_steps
        config, _ = preset(bench.preset, method, **{**overrides, **extra})
        yield label, config


def main(bench: BenchConfig) -> list[Measurement]:
    print(
        f"jax {jax.__version__} on {jax.devices()[0].platform} ({jax.device_count()} device(s)); "
        f"preset={bench.preset} setup={bench.setup} updates/call={bench.updates} repeats={bench.repeats}",
        flush=True,
    )
    programs = []
    for label, config in list(combinations(bench)):  # every config checked before any compile
        trainer = Trainer(config)
        state = jax.block_until_ready(jax.jit(trainer.init)(jax.random.key(bench.seed)))
        start = time.perf_counter()
        compiled = jax.jit(trainer.run, static_argnums=2).lower(state, trainer.env_params, bench.updates).compile()
        compile_s = time.perf_counter() - start
        _, metrics = jax.block_until_ready(compiled(state, trainer.env_params))  # warm-up
        env_run = env_only(trainer, bench.updates)
        jax.block_until_ready(env_run(trainer.env_params, jax.random.key(1)))
        programs.append((label, config, trainer, state, compiled, compile_s, metrics, env_run))
        print(f"  compiled {label} B={config.num_lanes} T={config.num_steps} in {compile_s:.1f} s", flush=True)

    times: dict[str, list[float]] = {p[0] + str(p[1].num_lanes): [] for p in programs}
    env_times: dict[str, list[float]] = {k: [] for k in times}
    for _ in range(bench.repeats):  # the programs take turns
        for label, config, trainer, state, compiled, _, _, env_run in programs:
            key = label + str(config.num_lanes)
            times[key].append(timed(lambda: compiled(state, trainer.env_params)))
            env_times[key].append(timed(lambda: env_run(trainer.env_params, jax.random.key(1))))

    results = []
    for label, config, trainer, state, compiled, compile_s, metrics, _ in programs:
        key = label + str(config.num_lanes)
        results.append(
            Measurement(
                label,
                config.num_lanes,
                config.num_steps,
                bench.updates,
                compile_s,
                min(times[key]),
                statistics.median(times[key]),
                float(np.sum(metrics["frames/useful"])),
                config.num_lanes * config.num_steps * bench.updates,
                temp_megabytes(compiled),
                min(env_times[key]),
            )
        )
    print_table(results)
    return results


def print_table(results: list[Measurement]) -> None:
    print()
    print(
        "| method, rollout, gradient | lanes | T | useful frames/s | stepped frames/s | useful % | updates/s | "
        "compile s | temp MB | env % | x first |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    first = results[0]
    per_useful = lambda m: m.best_s / max(m.useful_frames, 1.0)  # noqa: E731
    for m in results:
        temp = f"{m.temp_mb:.0f}" if m.temp_mb is not None else "-"
        print(
            f"| {m.label} | {m.lanes} | {m.num_steps} | {m.useful_fps:,.0f} | {m.stepped_fps:,.0f} | "
            f"{100 * m.useful_frames / m.stepped_frames:.0f}% | {m.updates / m.best_s:.1f} | {m.compile_s:.1f} | "
            f"{temp} | {100 * m.env_s / m.best_s:.1f}% | {per_useful(first) / per_useful(m):.2f} |"
        )
    print(
        "\n(best of the repeats; median update times are within "
        f"{max(100 * (m.median_s / m.best_s - 1) for m in results):.0f}% of the best)"
    )


if __name__ == "__main__":
    try:
        main(tyro.cli(BenchConfig))
    except ValueError as e:
        errors.fail(str(e))
    sys.exit(0)
