"""The paper's C-VAE comparison on a trained run:
`python -m experiments.cvae_compare --run runs/quick --windows 300`.

The run's last agent plays `--windows` training windows (it is not updated); every
successful episode gives the item ForeSIT's buffers would get, (s_0, g_tau, ŝ_tau) with
the critic's sub-goal.  On 80% of the items a C-VAE of ŝ_tau given [s_0 : g_tau] is fitted,
and two f_w of the run's shape are trained: one imagining ŝ_tau (ForeSIT), one imagining
the C-VAE's latent mean; their smooth-L1 losses on the other 20% are compared (the paper:
0.012 vs 0.018), beside the variance of each target (foresit_jax.cvae says why).
Writes `cvae_comparison.json` and `.md` into the run folder.
"""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import jax
import numpy as np

from experiments import runs
from experiments.tables import markdown_table

MIN_ITEMS = 10


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
    from foresit_jax.config import Config
    from foresit_jax.train import make_trainer

    info = runs.read_run_info(args.run)
    config = Config(**info["config"])
    if not config.pieces.imagination.trains_imagination:
        raise runs.UserError(f"{args.run} is a {config.method} run, whose f_w is not trained on sub-goals; "
                             "use a run of a method with ForeSIT's imagination (e.g. a3c+foresit)")  # fmt: skip
    if args.windows < 1 or args.epochs < 1:
        raise runs.UserError(f"--windows and --epochs must be >= 1, got {args.windows} and {args.epochs}")
    out = args.run / "cvae_comparison.json"
    if out.exists() and not args.overwrite:
        raise runs.UserError(f"{out} exists; pass --overwrite to replace it")
    trainer = make_trainer(config)
    like = trainer.init(jax.random.PRNGKey(args.seed))
    manager = runs.checkpoint_manager(args.run / "checkpoints", 100)
    step = manager.latest_step()
    if step is None:
        raise runs.UserError(f"{args.run / 'checkpoints'} holds no checkpoint; was the run interrupted before its first chunk?")
    items = collect_items(trainer, runs.restore(manager, step, like), args.windows, args.seed)
    result = compare(config, items, args.epochs, args.seed)
    if "direct" not in result:
        raise runs.UserError(f"only {result['items']} successful episodes in {args.windows} windows (at least {MIN_ITEMS} "
                             "needed); raise --windows")  # fmt: skip
    result["update"] = step
    runs.write_json(out, result)
    md = markdown(result, config, args.windows)
    out.with_suffix(".md").write_text(md)
    print(md)
    print(f"wrote {out} and {out.with_suffix('.md')}")
    return result


def collect_items(trainer, state, windows: int, seed: int) -> tuple[np.ndarray, ...]:
    """(s_0, g_tau, ŝ_tau) `[n, ...]` of the successful episodes the agent of training
    state `state` (not updated) ends in `windows` windows (`Trainer.collect_subgoal_items`)."""
    state = state._replace(key=jax.random.fold_in(state.key, seed))
    collect = jax.jit(trainer.collect_subgoal_items, static_argnums=2)
    items, _ = collect(state, trainer.env_params, windows)
    s_0, goal, subgoal, add = (np.asarray(x) for x in items)
    add = add.astype(bool)
    return s_0[add], goal[add], subgoal[add]


def compare(config, items: tuple[np.ndarray, ...], epochs: int, seed: int) -> dict:
    """The comparison on `collect_items`'s items: 80% to fit and 20% held out
    (`foresit_jax.cvae.compare_imagination_targets`); with fewer than MIN_ITEMS items,
    only {"items": n}."""
    from foresit_jax import cvae

    n = len(items[0])
    if n < MIN_ITEMS:
        return {"items": n}
    order = np.random.default_rng(seed).permutation(n)
    cut = int(0.8 * n)
    train = tuple(x[order[:cut]] for x in items)
    test = tuple(x[order[cut:]] for x in items)
    sizes = config.imagination_layer_sizes
    result = cvae.compare_imagination_targets(jax.random.PRNGKey(seed), train, test, layer_sizes=sizes,
                                              latent_size=min(sizes), epochs=epochs)  # fmt: skip
    result.update(items=n, train_items=cut, test_items=n - cut, latent_size=min(sizes))
    return result


def markdown(result: dict, config, windows: int, level: int = 1) -> str:
    """The comparison's table and notes (the result of `compare`)."""
    sizes, n, cut = config.imagination_layer_sizes, result["items"], result["train_items"]
    rows = [[label, f"{r['loss']:.4f}", f"{r['target_variance']:.4f}", f"{r['loss_over_variance']:.3f}", width]
            for label, r, width in (("f_w on the agent's states (ForeSIT)", result["direct"], sizes[-1]),
                                    ("f_w on the C-VAE's latent mean", result["cvae_latent"], min(sizes)))]  # fmt: skip
    header = ["f_w target", "held-out smooth-L1 loss", "target variance", "loss / variance", "width"]
    at = f", update {result['update']}" if "update" in result else ""
    return ("#" * level + f" Imagination loss: the agent's states vs a C-VAE's latent ({config.method}{at})\n\n"
            + markdown_table(rows, header)
            + f"\n\n{n} items from successful episodes in {windows} windows ({cut} to fit, {n - cut} held out, "
            "split at random: the held-out items come from the same training scenes and targets); "
            f"the C-VAE's held-out reconstruction {result['cvae_reconstruction']:.4f}, KL {result['cvae_kl']:.4f} "
            "(a KL near 0 means the latent carries little of the state). Paper: 0.012 vs 0.018.\n")  # fmt: skip


def cli(argv=None) -> None:
    runs.run_cli(Args, main, argv)


if __name__ == "__main__":
    cli(sys.argv[1:])
