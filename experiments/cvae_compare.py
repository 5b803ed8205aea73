"""The paper's C-VAE comparison on a trained run:
`python -m experiments.cvae_compare --run runs/quick --windows 300`.

The run's last agent plays `--windows` training windows (it is not updated); every
successful episode gives the item ForeSIT's buffers would get, (s_0, g_tau, ŝ_tau) with
the critic's sub-goal.  On 80% of the items a C-VAE of ŝ_tau given [s_0 : g_tau] is fitted,
and two f_w of the run's shape are trained: one imagining ŝ_tau (ForeSIT), one imagining
the C-VAE's latent mean; their smooth-L1 losses on the other 20% are compared (the paper:
0.012 vs 0.018), beside the variance of each target (experiments.analysis.cvae says why).
Writes `cvae_comparison.json` and `.md` into the run folder.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import jax

from experiments import errors
from experiments.reporting import cvae_comparison
from experiments import rundir
from experiments.running.models import read_trained
from foresit_jax.config import Config


@dataclasses.dataclass(frozen=True)
class Args:
    """Compare imagining the agent's states with imagining a C-VAE's latent of them."""

    run: Path
    """Run folder of a method that trains f_w (e.g. a3c+foresit), written by experiments.train."""
    windows: int = 300
    """Training windows the run's last agent plays to collect successful episodes."""
    epochs: int = 50
    """Epochs of the C-VAE and of each f_w over the collected items."""
    seed: int = 0
    """Seed of the collection, the split and the fits."""
    overwrite: bool = False
    """Replace existing cvae_comparison files."""


def main(args: Args) -> dict:
    info = rundir.read_run_info(args.run)
    config = Config(**info["config"])
    if not config.pieces.imagination_variant.trains_imagination:
        raise errors.UserError(
            f"{args.run} is a {config.method} run, whose f_w is not trained on sub-goals; "
            "use a run of a method with ForeSIT's imagination (e.g. a3c+foresit)"
        )
    if args.windows < 1 or args.epochs < 1:
        raise errors.UserError(f"--windows and --epochs must be >= 1, got {args.windows} and {args.epochs}")
    out = args.run / "cvae_comparison.json"
    if out.exists() and not args.overwrite:
        raise errors.UserError(f"{out} exists; pass --overwrite to replace it")
    trained = read_trained(args.run)
    if len(trained.seeds) != 1:
        raise errors.UserError(
            f"{args.run} holds {len(trained.seeds)} seeds; cvae_compare reads a run of one (train's)"
        )
    step, state = trained.update, jax.tree.map(lambda x: x[0], trained.states)
    items = cvae_comparison.collect_items(trained.trainer, state, args.windows, args.seed)
    result = cvae_comparison.compare(config, items, args.epochs, args.seed)
    if "direct" not in result:
        raise errors.UserError(
            f"only {result['items']} successful episodes in {args.windows} windows (at least {cvae_comparison.MIN_ITEMS} "
            "needed); raise --windows"
        )
    result["update"] = step
    rundir.write_json(out, result)
    md = cvae_comparison.markdown(result, config, args.windows)
    out.with_suffix(".md").write_text(md)
    print(md)
    print(f"wrote {out} and {out.with_suffix('.md')}")
    return result


def cli(argv=None) -> None:
    errors.run_cli(Args, main, argv)


if __name__ == "__main__":
    cli(sys.argv[1:])
