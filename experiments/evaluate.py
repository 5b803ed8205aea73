"""Re-evaluate a trained run: `python -m experiments.evaluate --run runs/x --split test`.

Loads the model selected on validation or, with `--which last`, the training state of the
last checkpoint (of a run folder of `train`, or of one written before its present format),
and writes results_<split>.json and .md into the run folder (refusing to replace existing
ones without --overwrite).
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path
from typing import Literal, Optional

import jax

from experiments import errors
from experiments.reporting import tables
from experiments.running import presets, selection, sweeps
from experiments import rundir
from experiments.running.models import read_trained
from foresit_jax.config import Config
from foresit_jax.evaluate import agent_params, evaluate


@dataclasses.dataclass(frozen=True)
class Args:
    """Evaluate a trained agent on the validation or test split."""

    run: Path
    """Run folder written by experiments.train (one seed)."""
    split: str = "test"
    """Split: val or test."""
    which: Literal["best", "last"] = "best"
    """The model selected on validation (best) or the last checkpoint (last)."""
    episodes_per_room: Optional[int] = None
    """Episodes per room type (default: the run's own count for the split: its
    test_episodes_per_room, 250 in the paper, or its val_episodes_per_room)."""
    actions: Literal["method", "greedy", "sampled"] = "method"
    """How actions are chosen: the method's own protocol (SAVN samples, ORG takes the
    argmax), or greedy (argmax) or sampled for any method."""
    seed: Optional[int] = None
    """Evaluation seed (default: the run's own keys, so the episodes are those train used:
    its test episodes on test, its validation episodes on val)."""
    overwrite: bool = False
    """Replace existing results files."""


def main(args: Args) -> dict:
    """Evaluate and write the results; returns them as written (NaN as None)."""
    if args.split not in ("val", "test"):
        raise errors.UserError(f"--split must be val or test, got {args.split!r}")
    info = rundir.read_run_info(args.run)
    config = Config(**info["config"])
    episodes = sweeps.episodes_per_room(args.run, args.split, given=args.episodes_per_room)
    if args.seed is not None:
        presets.check_seeds(args.seed)
    # The method's own protocol (sampled; greedy for ORG) writes the plain file names.
    greedy = {"method": None, "greedy": True, "sampled": False}[args.actions]
    mode = "" if args.actions == "method" else f"_{args.actions}"
    suffix = "" if (args.which, args.actions) == ("best", "method") else f"_{args.which}" + mode
    out_json = args.run / f"results_{args.split}{suffix}.json"
    if out_json.exists() and not args.overwrite:
        raise errors.UserError(f"{out_json} exists; pass --overwrite to replace it")
    rundir.claim(args.run)  # the one writer of the run folder, and writable, before any work

    trained = read_trained(args.run)
    if len(trained.seeds) != 1:
        raise errors.UserError(
            f"{args.run} holds {len(trained.seeds)} seeds; evaluate reads a run of one (train's); "
            "for a sweep's arms use experiments.compare or experiments.paper"
        )
    if args.which == "best":
        step, chosen = trained.selected_updates[0], jax.tree.map(lambda x: x[0], trained.selected)
    else:
        step = trained.update
        chosen = agent_params(jax.tree.map(lambda x: x[0], trained.states), config.sigma2_max, config.evaluation_noise)
    seed = trained.seeds[0]
    if args.seed is not None:
        key = jax.random.PRNGKey(args.seed)
    elif args.split == "test":
        key = selection.test_key(seed)
    else:
        key = selection.validation_key(seed)
    results = evaluate(chosen, config, args.split, key, episodes, greedy=greedy)
    rundir.write_json(out_json, {"selected_update": step, "which": args.which, "results": results})
    results = rundir.jsonable(results)  # as written: an empty L>=5 bucket is None (JSON null)
    title = f"{config.method}, seed {seed}: {args.split} split ({args.which} model, update {step})"
    md = tables.results_markdown(results, title)
    out_json.with_suffix(".md").write_text(md)
    print(md)
    print(f"wrote {out_json} and {out_json.with_suffix('.md')}")
    return results


def cli(argv=None) -> None:
    errors.run_cli(Args, main, argv)


if __name__ == "__main__":
    cli(sys.argv[1:])
