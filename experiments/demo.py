"""The environment at a glance: a random and an oracle policy on the test split, calibration checks, pictures.

    python -m experiments.demo                      # 1000 episodes (250 per room type), savn setup
    python -m experiments.demo --setup org --episodes 400 --out runs/demo_org
    python -m experiments.demo --layout house --out runs/demo_house   # houses (envs.houses)

Runs a uniformly random policy and the oracle (``env.optimal_action``) for the same
episodes (same start poses and targets) with the evaluation time limits (100 steps, 200
in living rooms), vmapped over episodes and jitted; prints SR and SPL overall and per room
type for both, and the environment's calibration figures with a PASS/FAIL mark each:

- the random policy's SR is at most 10%;
- 40-80% of episodes have an optimal length L^g >= 5 (the paper's L >= 5 bucket);
- the mean optimal length rises bathroom < bedroom < kitchen < living room;
- the oracle succeeds in every episode with SPL 100%.

In houses (``--layout house``; a room type is then the type of the target's room, the
limit 300 steps) the checks are the houses' own: the random policy's SR is at most 3%;
at least 70% of episodes have L^g >= 10; the oracle succeeds in every episode with SPL 100%.

Writes into --out (default runs/demo): for each room type a top-down picture of one test
scene with the oracle's trajectory (topdown_<room>.png) and the first-person view at its
start (view_<room>.png), and the tables (results.md).  Existing files are replaced only
with --overwrite.  Exit status: 0, 1 when a calibration check fails, 2 on a usage error.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path
from typing import Literal

import jax
import jax.numpy as jnp
import numpy as np
import tyro

import envs
from envs import catalog as C
from envs import render
from envs.metrics import LONG_PATH_MIN
from experiments.reporting.tables import markdown_table
from foresit_jax.rollout import EpisodeStats
from foresit_jax.evaluate import outcome_metrics, random_policy_rollout

RANDOM_SR_MAX = 10.0  # %
LONG_FRACTION_RANGE = (40.0, 80.0)  # % of episodes with L^g >= 5
LENGTH_ORDER = ("bathroom", "bedroom", "kitchen", "living_room")  # rising mean L^g
HOUSE_RANDOM_SR_MAX = 3.0  # % (measured 1.4% on the savn test houses)
HOUSE_LONG_MIN = 70.0  # % of episodes with L^g >= 10 in houses (measured 81%)
POLICIES = ("random", "oracle")


@dataclasses.dataclass(frozen=True)
class DemoConfig:
    """Random and oracle policies on the test split: SR/SPL, calibration checks, pictures."""

    episodes: int = 1000
    """episodes in all, split evenly over the four room types (1000: 250 each, as the paper)"""
    out: Path = Path("runs/demo")
    """folder for the pictures and results.md"""
    setup: Literal["savn", "org"] = "savn"
    """target setup (see docs/design.md)"""
    layout: Literal["room", "house"] = "room"
    """single rooms, or houses of 2-4 rooms (docs/houses.md)"""
    priors: bool = False
    """layouts with the regularities of real homes (docs/priors.md)"""
    overwrite: bool = False
    """replace files that already exist in --out"""
    seed: int = 0
    """PRNG seed (episodes and the random policy)"""


def output_files(out: Path) -> list[Path]:
    names = [f"{kind}_{room}.png" for room in C.ROOM_TYPES for kind in ("topdown", "view")]
    return [out / n for n in names] + [out / "results.md"]


def oracle_rollout(env, num_lanes: int, num_steps: int):
    """Jitted (params, key) -> (obs, state, EpisodeStats [lanes], poses) of the oracle
    (``env.optimal_action``), each lane's first episode; poses: [T, lanes, ...] the pose
    after each step, before any auto-reset (for the pictures).

    Keys are derived as `random_policy_rollout` derives them, so with the same key both
    policies play the same episodes (scene, target, start pose)."""
    vreset = jax.vmap(env.reset, in_axes=(0, None))
    vstep = jax.vmap(env.step, in_axes=(0, 0, 0, None))
    voptimal = jax.vmap(env.optimal_action, in_axes=(0, None))
    vstep_state = jax.vmap(env.step_env, in_axes=(0, 0, 0, None))

    @jax.jit
    def rollout(params, key):
        key_reset, key_steps = jax.random.split(key)
        obs, state = vreset(jax.random.split(key_reset, num_lanes), params)
        zeros = jnp.zeros(num_lanes, jnp.int32)
        record = {"success": jnp.zeros(num_lanes, bool), "length": zeros, "optimal_length": zeros}

        def body(carry, key_t):
            state, active, record = carry
            _, key_env = jax.random.split(key_t)  # (the random policy's action key)
            action = voptimal(state, params)
            keys = jax.random.split(key_env, num_lanes)
            _, state_next, _, terminated, truncated, info = vstep(keys, state, action, params)
            _, after, *_ = vstep_state(keys, state, action, params)  # the pose before any auto-reset
            ending = active & (terminated | truncated)
            record = {
                k: jnp.where(ending, info[name], record[k])
                for k, name in (
                    ("success", "success"),
                    ("length", "episode_length"),
                    ("optimal_length", "optimal_length"),
                )
            }
            pose = (after.agent_pos, after.heading, after.horizon)
            return (state_next, active & ~ending, record), pose

        (_, active, record), poses = jax.lax.scan(
            body, (state, jnp.ones(num_lanes, bool), record), jax.random.split(key_steps, num_steps)
        )
        return obs, state, EpisodeStats(record["success"], record["length"], record["optimal_length"], ~active), poses

    return rollout


def metrics(outcomes: EpisodeStats) -> dict[str, float]:
    """SR, SPL, SR>=5, SPL>=5 in % (as evaluation computes them), mean L^g, share of
    L^g >= 5, episode count."""
    table = outcome_metrics(outcomes)
    optimal_length = np.asarray(outcomes.optimal_length)
    return {
        **{k: table[k] for k in ("SR", "SPL", "SR>=5", "SPL>=5")},
        "mean L^g": float(np.mean(optimal_length)),
        "L^g>=5 %": 100.0 * float(np.mean(optimal_length >= LONG_PATH_MIN)),
        "L^g>=10 %": 100.0 * float(np.mean(optimal_length >= 10)),
        "episodes": table["episodes"],
    }


def results_table(results: dict, layout: str = "room") -> str:
    cols = (
        "SR",
        "SPL",
        "SR>=5",
        "SPL>=5",
        "mean L^g",
        "L^g>=5 %",
        *(("L^g>=10 %",) if layout == "house" else ()),
        "episodes",
    )
    rows = [
        [
            policy,
            room.replace("_", " "),
            *(f"{results[policy][room][c]:.1f}" if c != "episodes" else str(results[policy][room][c]) for c in cols),
        ]
        for policy in POLICIES
        for room in ("overall",) + C.ROOM_TYPES
    ]
    return markdown_table(rows, ["policy", "room type", *cols])


def calibration(results: dict, layout: str = "room") -> list[tuple[str, bool]]:
    """(description, passed) of each calibration check (a layout's own, see the module doc)."""
    random_sr = results["random"]["overall"]["SR"]
    oracle = results["oracle"]["overall"]
    oracle_check = (
        f"oracle SR {oracle['SR']:.1f}% and SPL {oracle['SPL']:.1f}% are 100%",
        oracle["SR"] == 100.0 and oracle["SPL"] == 100.0,
    )
    if layout == "house":
        long10 = oracle["L^g>=10 %"]
        return [
            (f"random policy SR {random_sr:.1f}% <= {HOUSE_RANDOM_SR_MAX:.0f}%", random_sr <= HOUSE_RANDOM_SR_MAX),
            (f"episodes with L^g >= 10: {long10:.1f}% >= {HOUSE_LONG_MIN:.0f}%", long10 >= HOUSE_LONG_MIN),
            oracle_check,
        ]
    long = results["oracle"]["overall"]["L^g>=5 %"]
    lengths = [results["oracle"][room]["mean L^g"] for room in LENGTH_ORDER]
    lo, hi = LONG_FRACTION_RANGE
    order = " < ".join(f"{room.replace('_', ' ')} {v:.2f}" for room, v in zip(LENGTH_ORDER, lengths))
    return [
        (f"random policy SR {random_sr:.1f}% <= {RANDOM_SR_MAX:.0f}%", random_sr <= RANDOM_SR_MAX),
        (f"episodes with L^g >= {LONG_PATH_MIN}: {long:.1f}% in [{lo:.0f}%, {hi:.0f}%]", lo <= long <= hi),
        (f"mean L^g rises: {order}", all(a < b for a, b in zip(lengths, lengths[1:]))),
        oracle_check,
    ]


def main(config: DemoConfig) -> int:
    start = time.perf_counter()
    if config.episodes < len(C.ROOM_TYPES):
        print(
            f"error: --episodes must be at least {len(C.ROOM_TYPES)} (one per room type), got {config.episodes}",
            file=sys.stderr,
        )
        return 2
    files = output_files(config.out)
    existing = [f for f in files if f.exists()]
    if existing and not config.overwrite:
        print(
            f"error: {existing[0]} exists ({len(existing)} of the demo's files are in {config.out}); "
            "pass --overwrite to replace them or choose another --out",
            file=sys.stderr,
        )
        return 2
    config.out.mkdir(parents=True, exist_ok=True)

    per_room = [config.episodes // 4 + (i < config.episodes % 4) for i in range(4)]
    lanes = max(per_room)
    timings = {}
    t = time.perf_counter()
    rooms = {
        room: envs.make(
            "GridNav-v0",
            setup=config.setup,
            split="test",
            room_types=(room,),
            training=False,
            layout=config.layout,
            priors=config.priors,
            perception_range=config.perception_range,
        )
        for room in C.ROOM_TYPES
    }
    env = rooms[C.ROOM_TYPES[0]][0]
    timings["scene banks"] = time.perf_counter() - t
    num_steps = max(int(np.max(params.max_steps)) for _, params in rooms.values())

    key = jax.random.key(config.seed)
    results = {p: {} for p in POLICIES}
    pooled = {p: [] for p in POLICIES}
    pictures = {}
    for policy in POLICIES:
        t = time.perf_counter()
        if policy == "random":
            random = jax.jit(lambda params, key: random_policy_rollout(env, params, key, lanes, num_steps))
        else:
            oracle = oracle_rollout(env, lanes, num_steps)
        for i, room in enumerate(C.ROOM_TYPES):
            _, params = rooms[room]
            # The same key for both policies: the same episodes (scene, target, start pose).
            key_room = jax.random.fold_in(key, i)
            if policy == "random":
                outcomes = random(params, key_room)
            else:
                obs, state, outcomes, poses = oracle(params, key_room)
            outcomes = jax.tree.map(lambda x: np.asarray(x)[: per_room[i]], outcomes)  # noqa: B023
            if not outcomes.ended.all():
                raise RuntimeError(f"{room}: an episode outlived {num_steps} steps (the time limit should end it)")
            results[policy][room] = metrics(outcomes)
            pooled[policy].append(outcomes)
            if policy == "oracle":
                pictures[room] = (
                    params,
                    jax.tree.map(lambda x: np.asarray(x[0]), (obs, state)),
                    [np.asarray(p[:, 0]) for p in poses],
                    int(outcomes.length[0]),
                )
        timings[f"{policy} rollouts (compile included)"] = time.perf_counter() - t
        results[policy]["overall"] = metrics(jax.tree.map(lambda *x: np.concatenate(x), *pooled[policy]))

    t = time.perf_counter()
    for room, (params, (obs, state), (pos, heading, horizon), length) in pictures.items():
        trajectory = np.concatenate([np.asarray(state.agent_pos)[None], pos[:length]])
        final = state.replace(agent_pos=pos[length - 1], heading=heading[length - 1], horizon=horizon[length - 1])
        scene = int(state.scene)
        name = render.scene_name(int(np.asarray(params.bank.numbers[scene])), np.asarray(params.bank.room_types[scene]))
        target = env.categories[int(state.target)]
        title = (
            f"{name}, target {target}: oracle, "
            f"{length} actions (L^g = {int(state.optimal_length)})\narrow: final pose; dot: start"
        )
        render.render_topdown(
            params,
            scene,
            state=final,
            trajectory=trajectory,
            path=config.out / f"topdown_{room}.png",
            categories=env.categories,
            title=title,
        )
        render.render_view(
            obs,
            env.categories,
            path=config.out / f"view_{room}.png",
            max_depth=env.max_depth,
            title=f"{name.split(' (')[0]}, target {target}: first-person view at the start",
        )
    timings["pictures"] = time.perf_counter() - t

    table = results_table(results, config.layout)
    checks = calibration(results, config.layout)
    check_lines = [f"[{'PASS' if ok else 'FAIL'}] {text}" for text, ok in checks]
    family = f"{config.layout}s with priors" if config.priors else f"{config.layout}s"
    header = (
        f"GridNav-v0 {config.setup} setup, {family}, test split, {config.episodes} episodes "
        f"({', '.join(f'{n} {r}' for n, r in zip(per_room, C.ROOM_TYPES))}), evaluation time limits"
    )
    (config.out / "results.md").write_text(
        f"# Demo: random and oracle policies\n\n{header}\n\n{table}\n\n## Calibration\n\n"
        + "\n".join(f"- {line}" for line in check_lines)
        + "\n"
    )
    print(header)
    print()
    print(table)
    print()
    print("calibration:")
    for line in check_lines:
        print("  " + line)
    print()
    print(f"wrote {len(files)} files to {config.out}/ ({', '.join(f.name for f in files[:2])}, ...)")
    timings["total"] = time.perf_counter() - start
    print("time: " + ", ".join(f"{k} {v:.1f} s" for k, v in timings.items()))
    return 0 if all(ok for _, ok in checks) else 1


if __name__ == "__main__":
    sys.exit(main(tyro.cli(DemoConfig, prog="python -m experiments.demo")))
