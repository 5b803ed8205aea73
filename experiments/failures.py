"""How a trained run's episodes end: `python -m experiments.failures --run runs/x`.

`--run` is a run folder of `experiments.train` or a sweep folder of `experiments.sweep`
(every finished method, or `--methods`; every seed). Each seed's validation-selected model
plays the episodes of its test evaluation (the same keys and actions rule, so its success
share is its test SR) and every episode is replayed through the environment's oracle
(`experiments.analysis.probes.replay_oracle`). Printed and written to `failures.md` /
`failures.json` in the run folder (or `--out`):

* how the episodes end: success, a Done that failed, or the time limit;
* the failed Dones: after how many actions, how many said within the first 5, how far from
  success the oracle puts them (its actions to success at the Done), how many in the
  target's room (houses);
* the policy's mean probability of Done where Done would succeed (d = 1) and where it
  would not, and at the first 5 steps where it would not: a policy that gives up says
  Done early without the target; one that does not recognise the target passes it by;
* the same shares for the episodes that start in the target's room and those that start
  away (in single rooms every episode starts in the target's room).
"""

from __future__ import annotations

import dataclasses
import functools
import sys
from pathlib import Path
from typing import Optional

import jax
import jax.numpy as jnp
import numpy as np

from envs.catalog import ROOM_TYPES
from experiments import errors
from experiments.analysis.probes import EARLY_STEPS, episode_endings, replay_oracle
from experiments.reporting.tables import markdown_table
from experiments.running import selection, sweeps
from experiments import rundir
from experiments.running.models import models_of_run, models_of_sweep
from foresit_jax import rollout as rollout_lib
from foresit_jax.networks import build
from foresit_jax.rollout import ActOptions, BoundEnv
from foresit_jax.evaluate import Evaluator, base_acting


@dataclasses.dataclass(frozen=True)
class Args:
    """How a trained run's episodes end, replayed through the environment's oracle."""

    run: Path
    """A run folder (experiments.train) or a sweep folder (experiments.sweep): each seed's
    validation-selected model is played."""
    methods: tuple[str, ...] = ()
    """For a sweep: the methods (default: every finished one)."""
    split: str = "test"
    """Split: val or test (the episodes the run was validated or tested on)."""
    episodes_per_room: Optional[int] = None
    """Episodes per room type (default: the run's own count for the split)."""
    out: Optional[Path] = None
    """Folder for failures.md and failures.json (default: --run)."""
    overwrite: bool = False
    """Replace an existing failures.md / failures.json."""


def play(model, split: str, episodes: int, compiled: dict) -> dict:
    """The model's episodes of `split` as its evaluation plays them (its key, split over the
    room types as `Evaluator` splits it, its actions rule): `[B, T]` arrays of every room
    type's episodes, back to back, for `probes.episode_endings`. `compiled` keeps the
    Evaluator and the jitted functions of a config across calls (pass the same dict)."""
    config, params = model.config, model.selected
    if config not in compiled:
        where = Evaluator.scenes_of(config)
        evaluator = compiled.get(where) or Evaluator(*where)
        compiled[where] = evaluator
        rollout = jax.jit(
            functools.partial(
                rollout_lib.rollout,
                build(config),
                act=base_acting(config).act,
                options=ActOptions(greedy=config.pieces.greedy_evaluation),
            ),
            static_argnames="num_steps",
        )
        compiled[config] = (evaluator, rollout, jax.jit(functools.partial(replay_oracle, evaluator.env)))
    evaluator, rollout, replay = compiled[config]
    key = selection.test_key(model.seed) if split == "test" else selection.validation_key(model.seed)
    rooms = tuple(config.room_types or ROOM_TYPES)
    acting = params._replace(noise_variance=jnp.full((episodes,), params.noise_variance, jnp.float32))
    parts = []
    for room, k in zip(rooms, jax.random.split(key, len(rooms))):
        env_params = evaluator.room_params(split, room)
        num_steps = int(jnp.max(env_params.max_steps))
        reset_keys = jax.random.split(jax.random.split(k)[0], episodes)  # those rollout.rollout draws from k
        traj = rollout(acting, BoundEnv(evaluator.env, env_params), k, num_steps=num_steps, reset_keys=reset_keys)
        d, in_room = replay(env_params, reset_keys, traj.actions.T)
        p_done = jax.nn.softmax(traj.logits, -1)[..., -1]
        batch = {
            "valid": traj.valid.T,
            "success": traj.success.T,
            "actions": traj.actions.T,
            "p_done": p_done.T,
            "d": d,
            "in_room": in_room,
        }
        parts.append({name: np.asarray(v) for name, v in batch.items()})
    width = max(p["valid"].shape[1] for p in parts)  # rooms' time limits differ: pad the shorter

    def pad(x):
        return np.pad(x, ((0, 0), (0, width - x.shape[1])))

    return {name: np.concatenate([pad(p[name]) for p in parts]) for name in parts[0]}


def _pct(x) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{100 * x:.1f}"


def _num(x, digits: int = 0) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def markdown(report: dict[str, list[dict]], split: str, episodes: int) -> str:
    """One row per method and seed: how its episodes end, its failed Dones, its P(Done)."""
    ends, dones, starts = [], [], []
    for method, per_seed in report.items():
        for r in per_seed:
            a, f, p = r["all"], r["failed Done"], r["p_done"]
            ends.append(
                [method, r["seed"], a["episodes"], *(_pct(a[k]) for k in ("success", "failed Done", "time-out"))]
            )
            dones.append(
                [
                    method,
                    r["seed"],
                    f["episodes"],
                    _num(f["median actions"]),
                    _pct(f["early share"]),
                    _num(f["median d at Done"]),
                    _pct(f["in target room share"]),
                    _num(p["would succeed"], 3),
                    _num(p["would fail"], 3),
                    _num(p["would fail, early"], 3),
                ]
            )
            for group in ("start in target room", "start away"):
                g = r[group]
                if g["episodes"]:
                    starts.append(
                        [
                            method,
                            r["seed"],
                            group.removeprefix("start "),
                            g["episodes"],
                            *(_pct(g[k]) for k in ("success", "failed Done", "time-out")),
                        ]
                    )
    md = [
        f"# How the episodes end ({split} split, {episodes} episodes per room type)\n",
        markdown_table(ends, ["method", "seed", "episodes", "success %", "failed Done %", "time-out %"]) + "\n",
        "The failed Dones (actions into the episode, median; the share within the first "
        f"{EARLY_STEPS}; the oracle's actions to success at the Done, median; the share said in the target's room), "
        f"and the policy's mean probability of Done where Done would succeed, where it would not, and at the first "
        f"{EARLY_STEPS} steps where it would not:\n",
        markdown_table(
            dones,
            [
                "method",
                "seed",
                "failed Dones",
                "actions",
                f"within {EARLY_STEPS} %",
                "to success",
                "in target room %",
                "P(Done) would succeed",
                "would fail",
                "would fail, early",
            ],
        )
        + "\n",
        "By where the episode starts:\n",
        markdown_table(starts, ["method", "seed", "start", "episodes", "success %", "failed Done %", "time-out %"])
        + "\n",
    ]
    return "\n".join(md)


def models_of(args: Args) -> tuple[dict, int]:
    """({method: [Model per seed]}, episodes per room type) of a run or sweep folder."""
    if rundir.is_sweep(args.run):
        saved = sweeps.saved(args.run)
        finished = tuple(m for m in saved.methods if rundir.finished_seeds(rundir.arm_folder(args.run, m)))
        if not finished:
            raise errors.UserError(f"{args.run}: no finished method yet")
        models = models_of_sweep(args.run, args.methods or finished)
    else:
        if args.methods:
            raise errors.UserError("--methods is for a sweep folder; a run folder holds one method")
        models = models_of_run(args.run)
    return models, sweeps.episodes_per_room(args.run, args.split, next(iter(models)), args.episodes_per_room)


def main(args: Args) -> dict:
    if args.split not in ("val", "test"):
        raise errors.UserError(f"--split must be val or test, got {args.split!r}")
    folder = args.run if args.out is None else args.out
    out_md, out_json = folder / "failures.md", folder / "failures.json"
    if out_json.exists() and not args.overwrite:
        raise errors.UserError(f"{out_json} exists; pass --overwrite to replace it")
    models, episodes = models_of(args)
    if episodes < 1:
        raise errors.UserError(f"--episodes-per-room must be >= 1, got {episodes}")
    rundir.claim(folder)  # the one writer of the folder, and writable, before the work
    compiled = {}
    report = {
        method: [{"seed": m.seed, **episode_endings(**play(m, args.split, episodes, compiled))} for m in seeds]
        for method, seeds in models.items()
    }
    md = markdown(report, args.split, episodes)
    folder.mkdir(parents=True, exist_ok=True)
    rundir.write_json(out_json, {"split": args.split, "episodes_per_room": episodes, "methods": report})
    out_md.write_text(md)
    print(md)
    print(f"wrote {out_md} and {out_json}")
    return report


def cli(argv=None) -> None:
    errors.run_cli(Args, main, argv)


if __name__ == "__main__":
    cli(sys.argv[1:])
