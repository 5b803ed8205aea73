"""The foresight a layout family offers: `python -m experiments.foresight --setup savn --layout room`.

Imagination (f_w([s_0 : g])) and ORG's relation graph can only foresee where an unseen
target is if the first view says something about it. This measures how much: from
`--resets` random starts per split (drawn as `reset` draws them), on the starts whose first
view does not show the target, a logistic regression fitted on the train split's layouts
and scored on the test split's (held-out layouts, so memorised placements do not count)
predicts two things.

* **The first turn**: the side a shortest path turns to, left or right. This is whichever
  rotation leaves fewer actions to success (`GridNav.shortest_path_length` after `step`).
  Starts where both leave the same are left out.
* **The bearing** of the target (its nearest instance): ahead, right, behind or left of
  the agent's heading, by 90-degree sectors.

Each is predicted from three feature sets of the first observation:

* `geometry`: the view's layout. Per pixel, wall / floor / furniture / any object / nothing,
  and the depth. Which object stands where is not included.
* `view`: geometry, plus which semantic classes the view shows in its left and right halves.
* `view + target`: the view, plus the target category, and the target crossed with each
  class seen on each side (so a relation "the target stands by the sofa" can be expressed).

The **gain** is the accuracy of `view + target` minus that of `view`: what knowing the target
adds to what the view shows. Around 0, the layouts offer nothing to foresee. It is reported
with a 95% interval from a bootstrap over the test layouts (starts of one scene are not
independent). On layouts with priors (`--priors`, envs.priors) the report also splits the
test starts by whether the first view shows furniture of a kind the target stands by
(`anchor_in_view`): where a relation could show, and where it could not.

The pure part (`foresight_bound`, the features, the report) is
`experiments.reporting.foresight_bound`; this program draws the starts and writes the report.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import sys
import time
from pathlib import Path
from typing import Optional

import jax
import jax.numpy as jnp
import numpy as np

import envs
from envs import catalog as C
from experiments import errors
from experiments.reporting.foresight_bound import anchor_in_view, bearing_sector, features, foresight_bound, markdown
from experiments.reporting.foresight_bound import within_range
from experiments.running import presets
from experiments import rundir


@dataclasses.dataclass(frozen=True)
class Args:
    """Measure how well a first view foresees where an unseen target is, on held-out layouts."""

    setup: presets.SetupFlag = "savn"
    layout: str = "room"
    """Layout family: room or house."""
    priors: bool = False
    """Layouts with the regularities of real homes (envs.priors) instead of today's."""
    resets: int = 20000
    """Random starts drawn per split (train fits, test scores)."""
    seed: int = 0
    """Seed of the starts and of the bootstrap."""
    perception_range: Optional[float] = None
    """Emulate a perception range on the view (a lever, issue 58): objects farther than this many cells (depth) are
    seen but not resolved, one 'unresolved object' class, and a target that far does not count as in view (None: off)"""
    out: Optional[Path] = None
    """Also write foresight.md and foresight.json into this folder."""
    overwrite: bool = False
    """Replace the foresight.md and foresight.json already in --out (refused without it)."""


# ---------------------------------------------------------------------- the data
def collect(env, params, resets: int, key, perception_range: Optional[float] = None) -> dict[str, np.ndarray]:
    """From `resets` starts: the first views' feature sets, the turn and bearing labels (-1
    where a row is left out), the scene of each start (`group`) and whether the target is
    out of view (only those rows keep labels); with `perception_range`, the views as
    `within_range` sees them (a target beyond it is out of view)."""

    def one(k):
        obs, state = env.reset(k, params)
        sem, depth = env.view(state, params)
        here = env.shortest_path_length(state, params)
        after = [
            env.shortest_path_length(env.step(k, state, jnp.int32(a), params)[1], params)
            for a in (C.ROTATE_LEFT, C.ROTATE_RIGHT)
        ]
        return sem, depth, state.target, state.scene, state.agent_pos, state.heading, here, jnp.stack(after)

    sem, depth, target, scene, pos, heading, here, after = jax.tree.map(
        np.asarray, jax.jit(jax.vmap(one))(jax.random.split(key, resets))
    )
    bank = params.bank
    obj_cat = np.asarray(bank.obj_cat)
    seen, num_classes = within_range(
        sem, depth, perception_range, env.num_semantic, env.num_categories, C.NUM_STRUCTURAL
    )
    out_of_view = ~(seen == C.NUM_STRUCTURAL + target[:, None, None]).any(axis=(1, 2))
    turn = np.where(after[:, 0] < after[:, 1], 0, np.where(after[:, 1] < after[:, 0], 1, -1))
    bearing = np.full(resets, -1)
    for i in range(resets):
        cells = np.argwhere(obj_cat[scene[i]] == target[i])
        if not len(cells):
            continue
        d = cells - pos[i]
        bearing[i] = bearing_sector(d[np.argmin(np.abs(d).sum(1))], heading[i])
    keep = out_of_view & (here > 1)
    unresolved = None if perception_range is None else env.num_semantic
    data = features(seen, depth, target, num_classes, env.num_categories, C.NUM_STRUCTURAL, unresolved)
    data.update(
        turn=np.where(keep, turn, -1),
        bearing=np.where(keep, bearing, -1),
        group=np.asarray(bank.numbers)[scene],
        out_of_view=out_of_view,
    )
    if getattr(env, "priors", False):  # where the first view shows a piece the target stands by
        anchor = anchor_in_view(sem, target, env.setup)
        data["subsets"] = {"anchor in view": anchor, "anchor not in view": ~anchor}
    return data


# ---------------------------------------------------------------------- the CLI
def main(args: Args) -> dict:
    if importlib.util.find_spec("sklearn") is None:
        raise errors.UserError("experiments.foresight needs scikit-learn: pip install -e '.[paper]'")
    if args.perception_range is not None and not args.perception_range > 0:
        raise errors.UserError(
            f"--perception-range {args.perception_range}: give a positive number of cells, or leave it out for no range"
        )
    if args.resets < 100:
        raise errors.UserError(f"--resets {args.resets}: give at least 100 starts per split")
    presets.check_seeds(args.seed)
    if args.out is not None:  # before the minutes of measuring
        rundir.check_path(args.out)  # a name too long, a link that loops or leads nowhere
        if args.out.exists() and not args.out.is_dir():
            raise errors.UserError(f"--out {args.out} is a file, not a folder; choose another --out")
        taken = [name for name in ("foresight.md", "foresight.json") if (args.out / name).exists()]
        if taken and not args.overwrite:
            raise errors.UserError(
                f"{args.out} already holds {', '.join(taken)}; pass --overwrite to replace them, or "
                "choose another --out"
            )
    t0 = time.time()
    data = {}
    for i, split in enumerate(("train", "test")):
        env, params = envs.make(
            "GridNav-v0", setup=args.setup, split=split, layout=args.layout, training=False, priors=args.priors
        )
        data[split] = collect(
            env, params, args.resets, jax.random.fold_in(jax.random.PRNGKey(args.seed), i), args.perception_range
        )
    results = {label: foresight_bound(data["train"], data["test"], label, args.seed) for label in ("turn", "bearing")}
    md = markdown(results, time.time() - t0, args.setup, args.layout, args.priors, args.resets, args.perception_range)
    print(md)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "foresight.md").write_text(md)
        rundir.write_json(
            args.out / "foresight.json", {"args": rundir.jsonable(dataclasses.asdict(args)), "results": results}
        )
    return results


def cli(argv=None) -> dict:
    return errors.run_cli(Args, main, argv)


if __name__ == "__main__":
    cli(sys.argv[1:])
