"""How a trained run's episodes end: `python -m experiments.failures --run runs/x`.

The run's validation-selected model plays the episodes of its test evaluation (the same
keys and actions rule, so its success share is the run's test SR) and every episode is
replayed through the environment's oracle (`foresit_jax.probes.replay_oracle`). Printed
and written to `failures.md` / `failures.json` in the run folder (or `--out`):

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
from experiments import runs, selection
from experiments.tables import markdown_table


@dataclasses.dataclass(frozen=True)
class Args:
    """How a trained run's episodes end, replayed through the environment's oracle."""

    run: Path
    """A run folder of experiments.train (its validation-selected model is played)."""
    split: str = "test"
    """Split: val or test (the episodes the run was validated or tested on)."""
    episodes_per_room: Optional[int] = None
    """Episodes per room type (default: the run's own count for the split)."""
    out: Optional[Path] = None
    """Folder for failures.md and failures.json (default: --run)."""
    overwrite: bool = False
    """Replace an existing failures.md / failures.json."""


def play(model, split: str, episodes: int) -> dict:
    """The model's episodes of `split` as the run's evaluation plays them (its key, split
    over the room types as `Evaluator` splits it, its actions rule): `[B, T]` arrays of
    every room type's episodes, back to back, for `probes.episode_endings`."""
    from foresit_jax.agent import Agent, BoundEnv
    from foresit_jax.evaluate import Evaluator
    from foresit_jax.probes import replay_oracle

    config, params = model.config, model.selected
    evaluator = Evaluator(config.setup, config.layout)
    env = evaluator.env
    key = selection.test_key(model.seed) if split == "test" else selection.validation_key(model.seed)
    rooms = tuple(config.room_types or ROOM_TYPES)
    rollout = jax.jit(functools.partial(Agent(config).rollout, greedy=config.pieces.greedy_evaluation),
                      static_argnames="num_steps")  # fmt: skip
    replay = jax.jit(functools.partial(replay_oracle, env))
    acting = params._replace(noise_variance=jnp.full((episodes,), params.noise_variance, jnp.float32))
    parts = []
    for room, k in zip(rooms, jax.random.split(key, len(rooms))):
        env_params = evaluator.room_params(split, room)
        num_steps = int(jnp.max(env_params.max_steps))
        reset_keys = jax.random.split(jax.random.split(k)[0], episodes)  # those Agent.rollout draws from k
        traj = rollout(acting, BoundEnv(env, env_params), k, num_steps=num_steps, reset_keys=reset_keys)
        d, in_room = replay(env_params, reset_keys, traj.actions.T)
        p_done = jax.nn.softmax(traj.logits, -1)[..., -1]
        batch = {"valid": traj.valid.T, "success": traj.success.T, "actions": traj.actions.T, "p_done": p_done.T,
                 "d": d, "in_room": in_room}  # fmt: skip
        parts.append({k: np.asarray(v) for k, v in batch.items()})
    width = max(p["valid"].shape[1] for p in parts)  # rooms' time limits differ: pad the shorter
    pad = lambda x: np.pad(x, ((0, 0), (0, width - x.shape[1])))
    return {k: np.concatenate([pad(p[k]) for p in parts]) for k in parts[0]}


def _pct(x) -> str:
    return "n/a" if not np.isfinite(x) else f"{100 * x:.1f}"


def markdown(report: dict, title: str) -> str:
    from foresit_jax.probes import EARLY_STEPS

    groups = [("all", "all episodes"), ("start in target room", "start in the target's room"),
              ("start away", "start in another room")]  # fmt: skip
    cells = [[name, report[g]["episodes"], *(_pct(report[g][k]) for k in ("success", "failed Done", "time-out"))]
             for g, name in groups if report[g]["episodes"]]  # fmt: skip
    f, p = report["failed Done"], report["p_done"]
    md = [f"# How the episodes end: {title}\n",
          markdown_table(cells, ["episodes", "count", "success %", "failed Done %", "time-out %"]) + "\n",
          f"Failed Dones ({f['episodes']}): median {f['median actions']:.0f} actions into the episode, "
          f"{_pct(f['early share'])}% within the first {EARLY_STEPS}; the oracle's actions to success at the Done, "
          f"median {f['median d at Done']:.0f}; {_pct(f['in target room share'])}% said in the target's room.\n",
          f"The policy's mean probability of Done: {p['would succeed']:.3f} where Done would succeed, "
          f"{p['would fail']:.3f} where it would not ({p['would fail, early']:.3f} at the first {EARLY_STEPS} steps).\n"]  # fmt: skip
    return "\n".join(md)


def main(args: Args) -> dict:
    from experiments import probe
    from foresit_jax.probes import episode_endings

    if args.split not in ("val", "test"):
        raise runs.UserError(f"--split must be val or test, got {args.split!r}")
    folder = args.run if args.out is None else args.out
    out_md, out_json = folder / "failures.md", folder / "failures.json"
    if out_json.exists() and not args.overwrite:
        raise runs.UserError(f"{out_json} exists; pass --overwrite to replace it")
    info = runs.read_run_info(args.run)
    episodes = info["schedule"][f"{args.split}_episodes_per_room"] if args.episodes_per_room is None else args.episodes_per_room
    if episodes < 1:
        raise runs.UserError(f"--episodes-per-room must be >= 1, got {episodes}")
    ((model,),) = probe.models_of_run(args.run).values()
    runs.claim(folder)  # the one writer of the folder, and writable, before the work
    report = episode_endings(**play(model, args.split, episodes))
    title = f"{model.config.method}, seed {model.seed}, {args.split} split ({episodes} episodes per room type)"
    md = markdown(report, title)
    folder.mkdir(parents=True, exist_ok=True)
    runs.write_json(out_json, {"split": args.split, "episodes_per_room": episodes, **report})
    out_md.write_text(md)
    print(md)
    print(f"wrote {out_md} and {out_json}")
    return report


def cli(argv=None) -> None:
    runs.run_cli(Args, main, argv)


if __name__ == "__main__":
    cli(sys.argv[1:])
