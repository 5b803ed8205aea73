"""Environment throughput: env steps per second of a jitted ``lax.scan`` over a vmapped step.

    python -m benchmarks.bench_env --batch-sizes 1 64 1024 4096 --steps 200 \
        --mode both --compare xminigrid

For each batch size B, one jitted function runs ``steps`` steps of ``jax.vmap(env.step)``
with uniformly random actions (auto-reset included, as in training) and carries the
observation, so nothing the step computes is dead code.  It is compiled ahead of time
(the compile column) and run once; then the envs of one batch size are timed in turn,
``repeats`` rounds, each call after ``block_until_ready`` (round-robin, so that a shared
machine's drifting load hits every env alike); the table gives the best and the median of
B * steps / seconds.  The scene bank is passed
as an argument (not folded into the program as a constant).

Modes: ``precomputed`` gathers each pose's view from the scene bank's table (the default
env); ``raycast`` casts the view at every step (``precomputed_views=False``; timed over
``--raycast-steps`` steps per call, since it is about a hundred times slower).  Timings on
a shared machine are noisy: compare the best column of one run.
``--layouts room house`` times single rooms and houses (``layout="house"``) in the same
rounds and prints the ratio houses / rooms per batch size; ``--priors False True`` times
today's layouts and those with priors (envs.priors) and prints the ratio priors / today's;
``--perception-ranges 4`` also times each env with that perception range (GridNav's
``perception_range``) and prints the ratio ranged / unranged.
``--compare xminigrid`` measures XLand-MiniGrid's ``MiniGrid-DoorKey-8x8`` the same way
(its ``GymAutoResetWrapper``, random actions, observation carried) and prints the ratio
ours / DoorKey per batch size.
"""

from __future__ import annotations

import dataclasses
import os
import statistics
import sys
import time
from typing import Literal

import jax
import tyro

import envs
from experiments.reporting.tables import markdown_table

XMINIGRID_ENV = "MiniGrid-DoorKey-8x8"
XMINIGRID_INSTALL = 'xminigrid is not installed: pip install xminigrid==0.9.3 (or pip install -e ".[bench]")'


@dataclasses.dataclass(frozen=True)
class BenchConfig:
    """Steps per second of GridNav-v0 (and optionally XLand-MiniGrid DoorKey-8x8)."""

    batch_sizes: tuple[int, ...] = (1, 64, 1024, 4096)
    """numbers of environments stepped in parallel (vmap)"""
    steps: int = 200
    """steps per timed call (the length of the scan)"""
    raycast_steps: int = 20
    """steps per timed call in raycast mode (ray casting every step is ~100x slower)"""
    repeats: int = 5
    """timed calls per measurement (best and median are reported)"""
    mode: Literal["precomputed", "raycast", "both"] = "both"
    """view rendering: table gather, ray casting at every step, or both"""
    compare: Literal["none", "xminigrid"] = "none"
    """also measure XLand-MiniGrid's MiniGrid-DoorKey-8x8 (pip install xminigrid==0.9.3)"""
    setup: Literal["savn", "org"] = "savn"
    """GridNav target setup"""
    split: Literal["train", "val", "test"] = "train"
    """GridNav scene split (train: 80 rooms, 60 houses)"""
    layouts: tuple[Literal["room", "house"], ...] = ("room",)
    """GridNav layouts to time: single rooms, houses (envs.houses) or both (then their ratio)"""
    priors: tuple[bool, ...] = (False,)
    """today's layouts (False), those with priors (True, envs.priors) or both (then their ratio)"""
    perception_ranges: tuple[float, ...] = ()
    """also time each env with these perception ranges (cells; GridNav's perception_range), then the ratio"""
    seed: int = 0
    """PRNG seed"""


@dataclasses.dataclass(frozen=True)
class Measurement:
    name: str
    batch_size: int
    compile_s: float
    best_sps: float
    median_sps: float


def compile_rollout(rollout, args: tuple, key):
    """(compiled rollout, compile seconds); runs it once (warm-up)."""
    start = time.perf_counter()
    compiled = rollout.lower(*args, key).compile()
    compile_s = time.perf_counter() - start
    jax.block_until_ready(compiled(*args, key))
    return compiled, compile_s


def time_once(compiled, args: tuple, key, batch_size: int, steps: int) -> float:
    """Steps per second of one call of the compiled rollout."""
    key = jax.block_until_ready(key)
    start = time.perf_counter()
    jax.block_until_ready(compiled(*args, key))
    return batch_size * steps / (time.perf_counter() - start)


def gridnav_rollout(
    precomputed_views: bool,
    setup: str,
    split: str,
    batch_size: int,
    steps: int,
    layout: str = "room",
    priors: bool = False,
    perception_range: float | None = None,
):
    """(jitted rollout(params, carry, key) -> carry, (params, carry)) for GridNav-v0.

    The scene bank is an argument, not a constant folded into the program."""
    env, params = envs.make(
        "GridNav-v0",
        setup=setup,
        split=split,
        precomputed_views=precomputed_views,
        layout=layout,
        priors=priors,
        perception_range=perception_range,
    )
    vstep = jax.vmap(env.step, in_axes=(0, 0, 0, None))

    @jax.jit
    def rollout(params, carry, key):
        def body(carry, key_t):
            obs, state = carry
            key_act, key_env = jax.random.split(key_t)
            action = jax.random.randint(key_act, (batch_size,), 0, env.num_actions)
            obs, state, reward, terminated, truncated, info = vstep(
                jax.random.split(key_env, batch_size), state, action, params
            )
            return (obs, state), None

        carry, _ = jax.lax.scan(body, carry, jax.random.split(key, steps))
        return carry

    reset = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))
    carry = reset(jax.random.split(jax.random.key(1), batch_size), params)
    return rollout, (params, carry)


def xminigrid_rollout(batch_size: int, steps: int):
    """(jitted rollout(timestep, key) -> timestep, (timestep,)) for XLand-MiniGrid DoorKey-8x8."""
    import xminigrid
    from xminigrid.wrappers import GymAutoResetWrapper

    env, env_params = xminigrid.make(XMINIGRID_ENV)
    env = GymAutoResetWrapper(env)
    num_actions = env.num_actions(env_params)
    vstep = jax.vmap(env.step, in_axes=(None, 0, 0))

    @jax.jit
    def rollout(timestep, key):
        def body(timestep, key_t):
            action = jax.random.randint(key_t, (batch_size,), 0, num_actions)
            return vstep(env_params, timestep, action), None

        timestep, _ = jax.lax.scan(body, timestep, jax.random.split(key, steps))
        return timestep

    reset = jax.jit(jax.vmap(env.reset, in_axes=(None, 0)))
    timestep = reset(env_params, jax.random.split(jax.random.key(1), batch_size))
    return rollout, (timestep,)


def have_xminigrid() -> bool:
    try:
        import xminigrid  # noqa: F401
    except ImportError:
        return False
    return True


def main(config: BenchConfig) -> int:
    start = time.perf_counter()
    if config.compare == "xminigrid" and not have_xminigrid():
        print(f"error: {XMINIGRID_INSTALL}", file=sys.stderr)
        return 2
    if (
        not config.batch_sizes
        or min(config.batch_sizes) < 1
        or min(config.steps, config.raycast_steps, config.repeats) < 1
    ):
        print("error: --batch-sizes, --steps, --raycast-steps and --repeats must be positive", file=sys.stderr)
        return 2
    modes = {"precomputed": (True,), "raycast": (False,), "both": (True, False)}[config.mode]
    print(
        f"jax {jax.__version__} on {jax.devices()[0].platform} ({jax.device_count()} device(s), {os.cpu_count()} CPU cores); "
        f"repeats {config.repeats}; GridNav-v0 setup={config.setup} split={config.split} layouts={list(config.layouts)}"
    )
    key = jax.random.key(config.seed)
    results: list[tuple[Measurement, int]] = []
    for batch_size in config.batch_sizes:
        jobs = []
        for layout in config.layouts:
            for priors in config.priors:
                for precomputed in modes:
                    for reach in (None, *config.perception_ranges):
                        steps = config.steps if precomputed else config.raycast_steps
                        name = (
                            f"GridNav {'precomputed' if precomputed else 'raycast'}"
                            + ("" if layout == "room" else " house")
                            + (" priors" if priors else "")
                            + ("" if reach is None else f" range {reach:g}")
                        )
                        build = lambda p=precomputed, n=steps, lay=layout, pr=priors, r=reach: gridnav_rollout(  # noqa: E731
                            p, config.setup, config.split, batch_size, n, lay, pr, r
                        )
                        jobs.append((name, steps, build))
        if config.compare == "xminigrid":
            jobs.append(
                (f"xminigrid {XMINIGRID_ENV}", config.steps, lambda: xminigrid_rollout(batch_size, config.steps))
            )
        # Compile everything of this batch size first, then time round-robin: on a shared
        # machine the load drifts, and interleaving exposes every env to the same drift.
        compiled = []
        for name, steps, build in jobs:
            rollout, args = build()
            fn, compile_s = compile_rollout(rollout, args, key)
            compiled.append((name, steps, fn, args, compile_s, []))
        for i in range(config.repeats):
            key_i = jax.random.fold_in(key, i + 1)
            for name, steps, fn, args, compile_s, rates in compiled:
                rates.append(time_once(fn, args, key_i, batch_size, steps))
        for name, steps, fn, args, compile_s, rates in compiled:
            results.append((Measurement(name, batch_size, compile_s, max(rates), statistics.median(rates)), steps))
            print(f"  measured {name:32s} B={batch_size:<5d} best {max(rates):14,.0f} steps/s", flush=True)

    print()
    rows = [
        [m.name, m.batch_size, steps, f"{m.best_sps:,.0f}", f"{m.median_sps:,.0f}", f"{m.compile_s:.2f}"]
        for m, steps in results
    ]
    print(
        markdown_table(rows, ("env", "batch", "steps", "best steps/s", "median steps/s", "compile s"), align="<>>>>>")
    )
    if config.compare == "xminigrid":
        print()
        print(f"ratio ours / {XMINIGRID_ENV} (best steps/s)")
        reference = {m.batch_size: m.best_sps for m, _ in results if m.name.startswith("xminigrid")}
        for m, _ in results:
            if m.name.startswith("GridNav"):
                print(f"  {m.name:20s} B={m.batch_size:<5d} {m.best_sps / reference[m.batch_size]:6.2f}x")
    best = {(m.name, m.batch_size): m.best_sps for m, _ in results}
    for wanted, label, suffix in (
        (set(config.layouts) == {"room", "house"}, "houses / rooms", " house"),
        (set(config.priors) == {False, True}, "priors / today's layouts", " priors"),
        *((True, f"range {r:g} / no range", f" range {r:g}") for r in config.perception_ranges),
    ):
        if not wanted:
            continue
        print()
        print(f"ratio {label} (best steps/s)")
        for m, _ in results:
            if m.name.endswith(suffix):
                base = best[(m.name.removesuffix(suffix), m.batch_size)]
                print(f"  {m.name.removesuffix(suffix):28s} B={m.batch_size:<5d} {m.best_sps / base:6.2f}x")
    print(f"\ntotal time {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(tyro.cli(BenchConfig)))
