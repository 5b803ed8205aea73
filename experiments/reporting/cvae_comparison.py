"""The paper's C-VAE comparison on a trained agent (`experiments.cvae_compare` runs it on a
run folder, `experiments.paper` on its sweeps): collect the successful episodes' items,
fit a C-VAE and two f_w, compare their held-out losses; `experiments.analysis.cvae` has the fits."""

from __future__ import annotations

import functools

import jax
import numpy as np

from experiments.analysis import cvae
from experiments.reporting.tables import markdown_table
from foresit_jax.train import collect_subgoal_items

MIN_ITEMS = 10


def collect_items(trainer, state, windows: int, seed: int) -> tuple[np.ndarray, ...]:
    """(s_0, g_tau, ŝ_tau) `[n, ...]` of the successful episodes the agent of training
    state `state` (not updated) ends in `windows` windows (`foresit_jax.train.collect_subgoal_items`)."""
    state = state._replace(key=jax.random.fold_in(state.key, seed))
    collect = jax.jit(functools.partial(collect_subgoal_items, trainer), static_argnums=2)
    items, _ = collect(state, trainer.env_params, windows)
    s_0, goal, subgoal, add = (np.asarray(x) for x in items)
    add = add.astype(bool)
    return s_0[add], goal[add], subgoal[add]


def compare(config, items: tuple[np.ndarray, ...], epochs: int, seed: int) -> dict:
    """The comparison on `collect_items`'s items: 80% to fit and 20% held out
    (`experiments.analysis.cvae.compare_imagination_targets`); with fewer than MIN_ITEMS items,
    only {"items": n}."""
    n = len(items[0])
    if n < MIN_ITEMS:
        return {"items": n}
    order = np.random.default_rng(seed).permutation(n)
    cut = int(0.8 * n)
    train = tuple(x[order[:cut]] for x in items)
    test = tuple(x[order[cut:]] for x in items)
    sizes = config.imagination_layer_sizes
    result = cvae.compare_imagination_targets(
        jax.random.PRNGKey(seed), train, test, layer_sizes=sizes, latent_size=min(sizes), epochs=epochs
    )
    result.update(items=n, train_items=cut, test_items=n - cut, latent_size=min(sizes))
    return result


def markdown(result: dict, config, windows: int, level: int = 1) -> str:
    """The comparison's table and notes (the result of `compare`)."""
    sizes, n, cut = config.imagination_layer_sizes, result["items"], result["train_items"]
    rows = [
        [label, f"{r['loss']:.4f}", f"{r['target_variance']:.4f}", f"{r['loss_over_variance']:.3f}", width]
        for label, r, width in (
            ("f_w on the agent's states (ForeSIT)", result["direct"], sizes[-1]),
            ("f_w on the C-VAE's latent mean", result["cvae_latent"], min(sizes)),
        )
    ]
    header = ["f_w target", "held-out smooth-L1 loss", "target variance", "loss / variance", "width"]
    at = f", update {result['update']}" if "update" in result else ""
    return (
        "#" * level
        + f" Imagination loss: the agent's states vs a C-VAE's latent ({config.method}{at})\n\n"
        + markdown_table(rows, header)
        + f"\n\n{n} items from successful episodes in {windows} windows ({cut} to fit, {n - cut} held out, "
        "split at random: the held-out items come from the same training scenes and targets); "
        f"the C-VAE's held-out reconstruction {result['cvae_reconstruction']:.4f}, KL {result['cvae_kl']:.4f} "
        "(a KL near 0 means the latent carries little of the state). Paper: 0.012 vs 0.018.\n"
    )
