"""Training throughput of the paper-size agent: frames/s, FLOP/s against a matmul roofline,
the environment's share of the time, compile time.

    python -m experiments.bench_train --lanes 16 64 256 --updates 2 --method a3c+foresit \
        --preset paper --gradient both

For each number of lanes B, one jitted ``Trainer.run`` of ``updates`` updates (each: a
rollout of one padded episode of T = num_steps steps per lane, then one gradient step) is
compiled, run once, then timed ``repeats`` times after ``block_until_ready`` from the
same state (so every repeat does the same work). The table gives:

* frames/s: B * T * updates / seconds (best repeat; the median in brackets). Padded
  steps count as frames, as everywhere in RL (the env does step them).
* padded: the share of masked steps (mean of the metric ``charts/padded_fraction``).
  Early in training (as here: a random policy ends episodes fast) it is ~80 %; the
  replay gradient skips most of that work, so its speed depends on it. ``--full-episodes``
  sets the policy's Done logit to -1e9, so every episode runs to the time limit and
  nothing is padded: the worst case for the replay.
* GFLOP/update and GFLOP/s: the FLOPs executed, from XLA's cost analysis
  (``.cost_analysis()['flops']``; a dict, or a list of dicts in some jax versions). XLA
  counts the body of a loop once, whatever its trip count (checked at start-up and
  printed; the timed, rolled program's own count is printed too, for comparison), and a
  conditional as its costliest branch. So one update is counted with every ``lax.scan``
  unrolled, every ``lax.cond`` taking its cheap branch, and every ``while_loop`` /
  ``fori_loop`` running zero times; then what did run is added, each part counted alone
  and multiplied by its trip count: the imagination (once per episode; every K steps
  for ``int``), the replay gradient's chunks beyond the first (from each update's valid
  steps), f_w's optimiser steps (epochs * M per trained lane). By default the HLO is
  counted as lowered (instant); ``--flops compiled`` counts the optimised HLO (minutes
  per measurement at the paper's sizes; ~5-15 % more: fusion duplicates some cheap ops).
* % roof: achieved FLOP/s over a float32 matmul roofline measured in the same run
  (``jnp.dot`` of two n x n float32 matrices, jitted, best of several; 2 n^3 / t).
* env %: the time of the environment alone (same B and T, uniformly random actions,
  ``vmap(env.step)`` in a ``lax.scan``, ``updates`` episodes) over the update's time.
* compile s: ``lower`` + ``compile`` of the timed program.

``--gradient both`` times the reference (``through_rollout``: differentiating through the
acting scan) and the default (``replay``) alternately in the same run, and prints their
ratio. Goals (from the issue): >= 40 % of the roofline at 64 lanes on a CPU, and the
environment under 5 % of the time.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import statistics
import sys
import time
from typing import Literal

import jax
import jax.numpy as jnp
import numpy as np
import optax
import tyro

from experiments.presets import preset
from foresit_jax import imagination
from foresit_jax.agent import input_gates_chunk_vjp, replay_chunk_rows
from foresit_jax.networks import lstm_input_kernel_t
from foresit_jax.train import Trainer

ROOFLINE_GOAL = 0.40  # of the float32 matmul roofline, at 64 lanes
ENV_SHARE_GOAL = 0.05  # of the update's time


@dataclasses.dataclass(frozen=True)
class BenchConfig:
    """Training throughput (frames/s, FLOP/s, env share) of one method at a preset's sizes."""

    lanes: tuple[int, ...] = (16, 64, 256)
    """numbers of env lanes (A3C agents) per update"""
    updates: int = 2
    """updates per timed call (the length of the jitted scan)"""
    repeats: int = 3
    """timed calls per measurement (best and median are reported)"""
    method: str = "a3c+foresit"
    """method (see foresit_jax.config.METHODS)"""
    preset: str = "paper"
    """preset giving the network sizes (num_lanes is overridden)"""
    gradient: Literal["replay", "through_rollout", "both"] = "replay"
    """how the gradient is computed (Trainer's `gradient`); both: time both, print the ratio"""
    full_episodes: bool = False
    """force every episode to the time limit (no padding): the replay's worst case"""
    roofline_size: int = 2048
    """n of the n x n @ n x n float32 matmul that measures the roofline"""
    flops: Literal["lowered", "compiled", "none"] = "lowered"
    """FLOPs from XLA's cost analysis of the unrolled update as lowered (instant), as
    compiled (minutes per measurement; ~10 % more), or not counted"""
    seed: int = 0
    """PRNG seed"""


@dataclasses.dataclass(frozen=True)
class Measurement:
    lanes: int
    gradient: str
    updates: int
    compile_s: float
    best_s: float
    median_s: float
    frames: int
    padded: float
    flops: float | None  # per timed call (all its updates)
    env_best_s: float

    @property
    def fps(self) -> float:
        return self.frames / self.best_s

    @property
    def median_fps(self) -> float:
        return self.frames / self.median_s


# ---------------------------------------------------------------------- timing helpers
def best_and_median(fn, repeats: int) -> tuple[float, float]:
    """(best, median) seconds of `fn()` (its result blocked on), over `repeats` calls."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - start)
    return min(times), statistics.median(times)


class Roofline:
    """FLOP/s of a jitted float32 n x n @ n x n matmul: the best of every `sample()`.

    Sampled at start-up and again between the timed calls, so that the roofline and the
    training see the same machine (other processes on a shared CPU move both)."""

    def __init__(self, n: int):
        self.n = n
        self.a = jax.random.normal(jax.random.key(0), (n, n), jnp.float32)
        self.b = jax.random.normal(jax.random.key(1), (n, n), jnp.float32)
        self.dot = jax.jit(jnp.dot).lower(self.a, self.b).compile()
        jax.block_until_ready(self.dot(self.a, self.b))
        self.best_s = math.inf

    def sample(self, repeats: int = 1) -> None:
        best, _ = best_and_median(lambda: self.dot(self.a, self.b), repeats)
        self.best_s = min(self.best_s, best)

    @property
    def flops_per_s(self) -> float:
        return 2.0 * self.n**3 / self.best_s


# ---------------------------------------------------------------------- FLOP counting
def xla_flops(stage) -> float:
    """'flops' of XLA's cost analysis of a `Lowered` or `Compiled` program (a dict, or a
    list of dicts, one per program, in some jax versions)."""
    analysis = stage.cost_analysis()
    if isinstance(analysis, (list, tuple)):
        return float(sum(a.get("flops", 0.0) for a in analysis))
    return float(analysis.get("flops", 0.0))


def count_flops(fn, *args, compiled: bool = False) -> float:
    """XLA's FLOPs of `jax.jit(fn)(*args)`: of the HLO as lowered (default: instant), or
    of the compiled, optimised HLO (`compiled=True`: minutes for an unrolled update; it
    counts ~10 % more at the paper's sizes, fusions duplicating some work)."""
    lowered = jax.jit(fn).lower(*args)
    return xla_flops(lowered.compile() if compiled else lowered)


def scan_trip_count_check() -> tuple[float, float]:
    """XLA's FLOPs of a 10-step scan of a matmul, rolled and unrolled (a rolled count equal
    to one step's means the loop body is counted once)."""
    x, w = jnp.ones((64, 256), jnp.float32), jnp.ones((256, 256), jnp.float32)

    def run(unroll):
        return lambda x, w: jax.lax.scan(lambda c, _: (c @ w, None), x, None, length=10, unroll=unroll)[0]

    return count_flops(run(1), x, w, compiled=True), count_flops(run(True), x, w, compiled=True)


@contextlib.contextmanager
def counting_control_flow():
    """While tracing: every `lax.scan` unrolled, every `lax.cond` takes its false branch
    (in this code base the cheap one: keep the imagined sub-goal), every `lax.while_loop`
    and `lax.fori_loop` runs zero times (the f_w training loop, the replay gradient's
    chunks). What did run of them is added back by `update_flops`."""
    scan, cond, while_loop, fori_loop = jax.lax.scan, jax.lax.cond, jax.lax.while_loop, jax.lax.fori_loop

    def unrolled_scan(*args, **kwargs):
        kwargs["unroll"] = True
        return scan(*args, **kwargs)

    def false_branch(pred, true_fun, false_fun, *operands, **kwargs):
        return false_fun(*operands)

    def no_iterations(*args, **kwargs):
        return args[-1] if args else kwargs["init_val"]

    jax.lax.scan, jax.lax.cond, jax.lax.while_loop, jax.lax.fori_loop = (
        unrolled_scan, false_branch, no_iterations, no_iterations
    )
    try:
        yield
    finally:
        jax.lax.scan, jax.lax.cond, jax.lax.while_loop, jax.lax.fori_loop = scan, cond, while_loop, fori_loop


def update_flops(trainer: Trainer, state, metrics: dict, compiled: bool = False) -> tuple[float, dict[str, float]]:
    """FLOPs XLA counts for the updates that produced `metrics` (stacked per update), and
    the parts: {'straight': per update, 'imagination': per renewal, 'replay_chunk': per
    computed chunk, 'fw_item_step': per f_w optimiser step}."""
    cfg, agent = trainer.config, trainer.agent
    lanes, steps = cfg.num_lanes, cfg.num_steps
    env_params = trainer.env_params
    with counting_control_flow():  # a fresh lambda: nothing traced before the patch is reused
        straight = count_flops(lambda s: trainer.update(s, env_params), state, compiled=compiled)
    parts = {"straight": straight}
    num_updates = len(np.asarray(metrics["losses/total_loss"]))
    total = straight * num_updates

    obs, _ = jax.vmap(trainer.env.reset, in_axes=(0, None))(jax.random.split(jax.random.key(0), lanes), env_params)
    hidden = jnp.zeros((lanes, cfg.hidden_size), jnp.float32)
    if agent.flags.uses_imagination:
        parts["imagination"] = count_flops(
            lambda w, s, g: agent._imagined_subgoal(w, s, g, jax.random.key(0), jnp.ones((lanes,))),
            state.imagination_params, hidden, obs["target"], compiled=compiled,
        )  # fmt: skip
        renewals = math.ceil(steps / cfg.int_interval) if agent.flags.reimagine_every_k else 1
        total += parts["imagination"] * renewals * num_updates

    if trainer.gradient == "replay":
        rows = replay_chunk_rows(steps, lanes)
        index = jnp.arange(rows) % lanes
        probs = jnp.full((lanes, cfg.num_actions), 1.0 / cfg.num_actions, jnp.float32)
        cotangent = jnp.ones((rows, 4 * cfg.hidden_size), jnp.float32)

        def chunk(params):
            kernel_t = lstm_input_kernel_t(params["params"]["encoder"]["lstm"])
            return input_gates_chunk_vjp(agent, params, obs, probs, kernel_t, index, cotangent)

        parts["replay_chunk"] = count_flops(chunk, state.params, compiled=compiled)
        # Chunk 0 is outside the loop (counted in 'straight'); the loop runs the others
        # that hold valid steps.
        valid_steps = np.asarray(metrics["losses/num_valid_steps"])
        chunks = int(np.sum(np.maximum(np.ceil(valid_steps / rows), 1) - 1))
        total += parts["replay_chunk"] * chunks

    trained = np.asarray(metrics.get("imagination/num_trained_lanes", np.zeros(num_updates)))
    if agent.flags.trains_imagination:
        optimizer, buffers = trainer.imagination_optimizer, state.buffers

        def item_step(w, s_0, goal, subgoal):
            loss, grads = jax.value_and_grad(lambda w: imagination.imagination_loss(agent.imagine, w, s_0, goal, subgoal))(w)
            updates, _ = optimizer.update(grads, optimizer.init(w), w)
            return loss, optax.apply_updates(w, updates)

        item = (buffers.s_0[0, 0], buffers.goal[0, 0], buffers.subgoal[0, 0])
        parts["fw_item_step"] = count_flops(item_step, state.imagination_params, *item, compiled=compiled)
        total += parts["fw_item_step"] * cfg.imagination_epochs * cfg.buffer_size * float(np.sum(trained))
    return total, parts


# ---------------------------------------------------------------------- what is timed
def never_done(trainer: Trainer, state):
    """The state with the policy's Done logit at -1e9: episodes run to the time limit."""
    def done_off(path, x):
        names = [getattr(k, "key", None) for k in path]
        return x.at[-1].set(-1e9) if names[-3:] == ["policy", "actor", "bias"] else x

    return state._replace(params=jax.tree_util.tree_map_with_path(done_off, state.params))


def env_only(trainer: Trainer, num_episodes: int):
    """Jitted `key -> observations`: `num_episodes` rollouts of the env alone, random actions."""
    env, lanes, steps = trainer.env, trainer.config.num_lanes, trainer.config.num_steps
    vstep = jax.vmap(env.step, in_axes=(0, 0, 0, None))

    def episode(env_params, key):
        k_reset, k_steps = jax.random.split(key)
        obs, state = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(k_reset, lanes), env_params)

        def step(carry, key):
            obs, state = carry
            k_act, k_env = jax.random.split(key)
            action = jax.random.randint(k_act, (lanes,), 0, env.num_actions)
            obs, state, reward, terminated, truncated, _ = vstep(jax.random.split(k_env, lanes), state, action, env_params)
            return (obs, state), reward

        (obs, _), rewards = jax.lax.scan(step, (obs, state), jax.random.split(k_steps, steps))
        return jnp.sum(rewards) + jnp.sum(obs["view"])  # keeps every step live

    def run(env_params, key):
        return jax.lax.map(lambda k: episode(env_params, k), jax.random.split(key, num_episodes))

    return jax.jit(run).lower(trainer.env_params, jax.random.key(0)).compile()


def measure(config: BenchConfig, lanes: int, gradients: list[str], roofline: Roofline) -> list[Measurement]:
    cfg, _ = preset(config.preset, config.method, num_lanes=lanes, num_updates=config.updates)
    trainers = {g: Trainer(cfg, gradient=g) for g in gradients}
    first = trainers[gradients[0]]
    state = jax.jit(first.init)(jax.random.key(config.seed))
    if config.full_episodes:
        state = never_done(first, state)

    compiled, compile_s, outputs = {}, {}, {}
    for g, trainer in trainers.items():
        start = time.perf_counter()
        compiled[g] = jax.jit(trainer.run, static_argnums=2).lower(state, trainer.env_params, config.updates).compile()
        compile_s[g] = time.perf_counter() - start
        outputs[g] = jax.block_until_ready(compiled[g](state, trainer.env_params))  # warm-up
    env_run = env_only(first, config.updates)
    jax.block_until_ready(env_run(first.env_params, jax.random.key(1)))

    # Alternate the programs, so that they share whatever else the machine is doing.
    times: dict[str, list[float]] = {g: [] for g in gradients + ["env"]}
    for _ in range(config.repeats):
        roofline.sample()
        for g, trainer in trainers.items():
            best, _ = best_and_median(lambda: compiled[g](state, trainer.env_params), 1)
            times[g].append(best)
        times["env"].append(best_and_median(lambda: env_run(first.env_params, jax.random.key(1)), 1)[0])

    results = []
    frames = lanes * cfg.num_steps * config.updates
    for g, trainer in trainers.items():
        metrics = outputs[g][1]
        flops = None
        if config.flops != "none":
            flops, parts = update_flops(trainer, state, metrics, compiled=config.flops == "compiled")
            rolled = xla_flops(compiled[g])
            print(
                f"    B={lanes} {g}: {flops / config.updates / 1e9:.1f} GFLOP/update executed; parts (GFLOP): "
                + ", ".join(f"{name} {value / 1e9:.3g}" for name, value in parts.items())
                + f"; XLA's count of the timed (rolled) program: {rolled / config.updates / 1e9:.1f} GFLOP/update"
            )  # fmt: skip
        results.append(Measurement(
            lanes, g, config.updates, compile_s[g], min(times[g]), statistics.median(times[g]), frames,
            float(np.mean(metrics["charts/padded_fraction"])), flops, min(times["env"]),
        ))  # fmt: skip
        print(f"  measured B={lanes:<4d} {g:16s} {results[-1].fps:10,.0f} frames/s", flush=True)
    return results


def print_table(results: list[Measurement], roofline: float) -> None:
    header = (
        f"| {'lanes':>5s} | {'gradient':16s} | {'frames/s best (median)':>23s} | {'padded':>6s} | "
        f"{'GFLOP/update':>12s} | {'GFLOP/s':>7s} | {'% roof':>6s} | {'env %':>5s} | {'compile s':>9s} |"
    )
    print(header)
    print("|" + "|".join("-" * len(c) for c in header.split("|")[1:-1]) + "|")
    for m in results:
        gflop = f"{m.flops / m.updates / 1e9:12.1f}" if m.flops is not None else f"{'-':>12s}"
        rate = f"{m.flops / m.best_s / 1e9:7.1f}" if m.flops is not None else f"{'-':>7s}"
        roof = f"{100 * m.flops / m.best_s / roofline:5.1f}%" if m.flops is not None else f"{'-':>6s}"
        fps = f"{m.fps:10,.0f} ({m.median_fps:9,.0f})"
        print(
            f"| {m.lanes:5d} | {m.gradient:16s} | {fps:>23s} | {abs(100 * m.padded):5.1f}% | {gflop} | {rate} | "
            f"{roof} | {100 * m.env_best_s / m.best_s:4.1f}% | {m.compile_s:9.1f} |"
        )


def main(config: BenchConfig) -> int:
    gradients = ["through_rollout", "replay"] if config.gradient == "both" else [config.gradient]
    print(
        f"jax {jax.__version__} on {jax.devices()[0].platform} ({jax.device_count()} device(s), "
        f"{jax.devices()[0].device_kind}); preset={config.preset} method={config.method} "
        f"updates/call={config.updates} repeats={config.repeats} full_episodes={config.full_episodes}"
    )
    roofline = Roofline(config.roofline_size)
    roofline.sample(10)
    print(f"float32 matmul roofline ({config.roofline_size}^3, best of 10): {roofline.flops_per_s / 1e9:.1f} GFLOP/s")
    if config.flops != "none":
        rolled, unrolled = scan_trip_count_check()
        print(
            f"XLA cost analysis of a 10-step scan of a matmul: {rolled:.3g} FLOPs rolled, {unrolled:.3g} unrolled "
            f"(x{unrolled / rolled:.0f}): "
            + ("loop bodies are counted once, so updates are counted unrolled (see --help)." if unrolled > rolled
               else "loops are counted with their trip counts.")  # fmt: skip
        )
    results: list[Measurement] = []
    for lanes in config.lanes:
        results.extend(measure(config, lanes, gradients, roofline))
    roofline.sample(10)
    roofline = roofline.flops_per_s
    print()
    print(f"roofline: {roofline / 1e9:.1f} GFLOP/s (best of all samples: start, between timed calls, end)")
    print_table(results, roofline)

    if config.gradient == "both":
        print()
        for lanes in config.lanes:
            ref, new = (next(m for m in results if m.lanes == lanes and m.gradient == g) for g in gradients)
            print(
                f"B={lanes:<4d} replay / through_rollout: x{ref.best_s / new.best_s:.2f} (best), "
                f"x{ref.median_s / new.median_s:.2f} (median)"
            )
    print()
    main_gradient = "replay" if "replay" in gradients else gradients[0]
    at_64 = [m for m in results if m.lanes == 64 and m.gradient == main_gradient]
    if at_64 and at_64[0].flops is not None:
        share = at_64[0].flops / at_64[0].best_s / roofline
        verdict = "met" if share >= ROOFLINE_GOAL else "NOT met"
        print(f"goal >= {ROOFLINE_GOAL:.0%} of the roofline at 64 lanes ({main_gradient}): {verdict} ({share:.1%})")
    else:
        print("goal >= 40% of the roofline at 64 lanes: not measured (needs --lanes 64 and FLOP counting)")
    mine = [m for m in results if m.gradient == main_gradient]
    worst = max(mine, key=lambda m: m.env_best_s / m.best_s)
    share = worst.env_best_s / worst.best_s
    verdict = "met" if share < ENV_SHARE_GOAL else "NOT met"
    print(f"goal environment < {ENV_SHARE_GOAL:.0%} of the time ({main_gradient}): {verdict} (at most {share:.1%}, B={worst.lanes})")
    return 0


if __name__ == "__main__":
    sys.exit(main(tyro.cli(BenchConfig)))
