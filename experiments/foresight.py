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
(`anchor_in_view`): where a relation could show, and where it could not. `foresight_bound` is the pure part, tested on synthetic data with a planted
relation and without one (tests/test_foresight.py).
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
from envs.priors import RELATIONS
from experiments import errors
from experiments.reporting.tables import markdown_table
from experiments.running import presets, rundir

FEATURE_SETS = ("geometry", "view", "view + target")
TURNS = ("left", "right")
BEARINGS = ("ahead", "right", "behind", "left")


@dataclasses.dataclass(frozen=True)
class Args:
    """Measure how well a first view foresees where an unseen target is, on held-out layouts."""

    setup: str = "savn"
    """Environment setup: savn or org."""
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


# ---------------------------------------------------------------------- the pure part
REGULARISATIONS = (0.003, 0.03, 0.3)  # sklearn's C (inverse L2 strength), chosen per fit


def fit_and_score(train_x, train_y, train_groups, test_x) -> tuple[np.ndarray, float]:
    """A multinomial logistic regression on standardised features, fitted on the train
    rows, its L2 strength chosen among `REGULARISATIONS` by 3-fold cross-validation over
    the train groups (layouts), so that a larger feature set is not held back by a penalty
    chosen for a smaller one: (its predicted class for each test row, the chosen C)."""
    from sklearn.linear_model import LogisticRegression
    from sklearn.model_selection import GroupKFold
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    def model(c):
        return make_pipeline(StandardScaler(), LogisticRegression(C=c, max_iter=3000))

    if len(np.unique(train_y)) < 2:
        return np.full(len(test_x), train_y[0]), float("nan")
    folds = list(GroupKFold(n_splits=min(3, len(np.unique(train_groups)))).split(train_x, train_y, train_groups))
    scores = [np.mean([np.mean(model(c).fit(train_x[a], train_y[a]).predict(train_x[b]) == train_y[b])
                       for a, b in folds]) for c in REGULARISATIONS]  # fmt: skip
    c = REGULARISATIONS[int(np.argmax(scores))]
    return model(c).fit(train_x, train_y).predict(test_x), c


def cluster_bootstrap(values: np.ndarray, groups: np.ndarray, rng, resamples: int = 2000) -> tuple[float, float]:
    """95% interval of the mean of `values` [N], resampling whole groups (the test layouts)
    with replacement."""
    names, index = np.unique(groups, return_inverse=True)
    sums = np.bincount(index, weights=values, minlength=len(names))
    counts = np.bincount(index, minlength=len(names))
    draws = rng.integers(0, len(names), size=(resamples, len(names)))
    means = sums[draws].sum(1) / np.maximum(counts[draws].sum(1), 1)
    return float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))


def foresight_bound(train: dict, test: dict, labels: str, seed: int = 0) -> dict:
    """Accuracy on the test rows of each feature set (`FEATURE_SETS`, the keys of `train`
    and `test`, each [N, F]) predicting `train[labels]` / `test[labels]` ([N] ints, -1 to
    leave a row out), the majority class's, and the gain of `view + target` over `view`
    with its 95% interval over the test groups (`test["group"]`, e.g. the layout; the train
    groups serve the cross-validation of `fit_and_score`).  Where `test["subsets"]` names
    boolean masks [N] of the test rows (e.g. "anchor in view"), the same accuracies and gain
    on each subset's rows, under `out["subsets"]`."""
    keep_train, keep_test = train[labels] >= 0, test[labels] >= 0
    y_train, y_test = train[labels][keep_train], test[labels][keep_test]
    out = {"train_samples": int(keep_train.sum()), "test_samples": int(keep_test.sum()),
           "test_groups": int(len(np.unique(test["group"][keep_test])))}  # fmt: skip
    if not len(y_test) or not len(y_train):
        return out
    majority = np.bincount(y_train).argmax()
    out["majority"] = float(np.mean(y_test == majority))
    out["test_shares"] = (np.bincount(y_test) / len(y_test)).tolist()  # each label's share of the test rows
    correct = {}
    for name in FEATURE_SETS:
        predicted, out[f"C {name}"] = fit_and_score(train[name][keep_train], y_train, train["group"][keep_train],
                                                    test[name][keep_test])  # fmt: skip
        correct[name] = (predicted == y_test).astype(float)
        out[name] = float(correct[name].mean())
    gain = correct["view + target"] - correct["view"]
    out["gain"] = float(gain.mean())
    out["gain_ci"] = cluster_bootstrap(gain, test["group"][keep_test], np.random.default_rng(seed))
    out["subsets"] = {}
    for name, mask in test.get("subsets", {}).items():
        rows = mask[keep_test]
        part = {"samples": int(rows.sum()), "share": float(rows.mean())}
        if rows.any():
            part.update({k: float(correct[k][rows].mean()) for k in FEATURE_SETS})
            part["gain"] = float(gain[rows].mean())
            part["gain_ci"] = cluster_bootstrap(gain[rows], test["group"][keep_test][rows], np.random.default_rng(seed))
        out["subsets"][name] = part
    return out


# ---------------------------------------------------------------------- the data
def within_range(sem: np.ndarray, depth: np.ndarray, perception_range: Optional[float], num_semantic: int,
                 num_targets: int, structural: int) -> tuple[np.ndarray, int]:  # fmt: skip
    """A perception range emulated on views (sem, depth [N, 3, W]): the object categories
    (`structural` .. `structural + num_targets`) seen farther than `perception_range` cells
    become one extra class, `num_semantic` ("an object, unresolved"); walls, floor and
    furniture stay as they are. Returns (the views' classes, the number of classes); None
    leaves the views alone."""
    if perception_range is None:
        return sem, num_semantic
    far = (sem >= structural) & (sem < structural + num_targets) & (depth > perception_range)
    return np.where(far, num_semantic, sem), num_semantic + 1


def features(sem: np.ndarray, depth: np.ndarray, target: np.ndarray, num_semantic: int, num_targets: int,
             structural: int, unresolved: Optional[int] = None) -> dict[str, np.ndarray]:  # fmt: skip
    """The feature sets of first views: sem, depth [N, 3, W] (envs' `view`, or
    `within_range`'s, whose `unresolved` class reads as an object in the geometry), the
    target category [N] (ints, the setup's category index)."""
    n, width = sem.shape[0], sem.shape[-1]
    # Every object category (and an unresolved object) -> one "object" class; every
    # furniture kind (layouts with priors: classes after the categories) -> furniture.
    coarse = np.where(sem >= structural + num_targets, C.SEM_FURNITURE, np.minimum(sem, structural))
    if unresolved is not None:
        coarse = np.where(sem == unresolved, structural, coarse)
    geometry = np.concatenate([np.eye(structural + 1)[coarse].reshape(n, -1),
                               depth.reshape(n, -1) / max(float(depth.max()), 1e-9)], axis=1)  # fmt: skip
    half = width // 2
    sides = np.stack([np.eye(num_semantic)[sem[..., :half]].any(axis=(1, 2)),
                      np.eye(num_semantic)[sem[..., half:]].any(axis=(1, 2))], axis=1).reshape(n, -1)  # [N, 2 * classes]
    view = np.concatenate([geometry, sides], axis=1)
    onehot = np.eye(num_targets)[target]
    crossed = (onehot[:, :, None] * sides[:, None, :]).reshape(n, -1)
    return {"geometry": geometry, "view": view, "view + target": np.concatenate([view, onehot, crossed], axis=1)}


def bearing_sector(offset, heading: int) -> int:
    """The sector (index into `BEARINGS`) of a cell at `offset` (d_row, d_col) from the agent
    heading `heading` (0 north, 45-degree steps clockwise): ahead within 45 degrees of the
    heading, then right, behind, left (a boundary goes clockwise)."""
    angle = np.degrees(np.arctan2(offset[1], -offset[0])) - 45.0 * heading  # clockwise from the heading
    return int(((angle + 45.0) % 360.0) // 90.0)


def collect(env, params, resets: int, key, perception_range: Optional[float] = None) -> dict[str, np.ndarray]:
    """From `resets` starts: the first views' feature sets, the turn and bearing labels (-1
    where a row is left out), the scene of each start (`group`) and whether the target is
    out of view (only those rows keep labels); with `perception_range`, the views as
    `within_range` sees them (a target beyond it is out of view)."""
    def one(k):
        obs, state = env.reset(k, params)
        sem, depth = env.view(state, params)
        here = env.shortest_path_length(state, params)
        after = [env.shortest_path_length(env.step(k, state, jnp.int32(a), params)[1], params)
                 for a in (C.ROTATE_LEFT, C.ROTATE_RIGHT)]  # fmt: skip
        return sem, depth, state.target, state.scene, state.agent_pos, state.heading, here, jnp.stack(after)

    sem, depth, target, scene, pos, heading, here, after = jax.tree.map(
        np.asarray, jax.jit(jax.vmap(one))(jax.random.split(key, resets)))
    bank = params.bank
    obj_cat = np.asarray(bank.obj_cat)
    seen, num_classes = within_range(sem, depth, perception_range, env.num_semantic, env.num_categories,
                                     C.NUM_STRUCTURAL)  # fmt: skip
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
    data.update(turn=np.where(keep, turn, -1), bearing=np.where(keep, bearing, -1),
                group=np.asarray(bank.numbers)[scene], out_of_view=out_of_view)  # fmt: skip
    if getattr(env, "priors", False):  # where the first view shows a piece the target stands by
        anchor = anchor_in_view(sem, target, env.setup)
        data["subsets"] = {"anchor in view": anchor, "anchor not in view": ~anchor}
    return data


def anchor_in_view(sem: np.ndarray, target: np.ndarray, setup: str) -> np.ndarray:
    """bool [N]: whether a first view (sem [N, 3, W]) shows furniture of a kind its target
    stands on or by (`envs.priors.RELATIONS`; False for targets placed by a zone)."""
    cats = C.categories(setup)
    classes = np.zeros((len(cats), C.num_semantic(setup, priors=True)), bool)
    for i, name in enumerate(cats):
        for kind in RELATIONS[name].on:
            classes[i, C.furniture_sem(setup, C.FURNITURE_KINDS.index(kind))] = True
    flat = sem.reshape(len(sem), -1)
    return classes[target[:, None], flat].any(axis=1)


# ---------------------------------------------------------------------- the CLI
def markdown(args: Args, results: dict, seconds: float) -> str:
    rows = []
    for label, r in results.items():
        if "gain" not in r:
            rows.append([label, r["train_samples"], r["test_samples"], *["n/a"] * 6])
            continue
        lo, hi = r["gain_ci"]
        rows.append([label, r["train_samples"], f"{r['test_samples']} ({r['test_groups']} layouts)",
                     *(f"{100 * r[k]:.1f}" for k in ("majority", *FEATURE_SETS)),
                     f"{100 * r['gain']:+.1f} [{100 * lo:+.1f}, {100 * hi:+.1f}]"])  # fmt: skip
        for name, part in r.get("subsets", {}).items():
            if "gain" in part:
                lo, hi = part["gain_ci"]
                rows.append([f"{label}, {name}", "", f"{part['samples']} ({100 * part['share']:.0f}%)", "",
                             *(f"{100 * part[k]:.1f}" for k in FEATURE_SETS),
                             f"{100 * part['gain']:+.1f} [{100 * lo:+.1f}, {100 * hi:+.1f}]"])  # fmt: skip
    shares = "; ".join(f"{label}: " + ", ".join(f"{name} {100 * share:.0f}%" for name, share in zip(names, r["test_shares"]))
                       for (label, r), names in zip(results.items(), (TURNS, BEARINGS)) if "test_shares" in r)  # fmt: skip
    family = f"{args.layout} layouts with priors" if args.priors else f"{args.layout} layouts"
    if args.perception_range is not None:
        family += f", objects resolved within {args.perception_range:g} cells (emulated on the view)"
    return (f"# Foresight: {args.setup} setup, {family}\n\n"
            f"{args.resets} starts per split; the starts whose first view does not show the target; fitted on the "
            "train layouts, accuracy (%) on the test layouts; the gain of the target over the view with its 95% "
            f"interval over the test layouts ({seconds:.0f} s).\n\n"
            + markdown_table(rows, ["predicts", "train starts", "test starts", "majority", *FEATURE_SETS,
                                    "gain from the target"]) + "\n"
            + (f"\nThe test starts' labels: {shares}.\n" if shares else ""))  # fmt: skip


def main(args: Args) -> dict:
    if importlib.util.find_spec("sklearn") is None:
        raise errors.UserError("experiments.foresight needs scikit-learn: pip install -e '.[paper]'")
    if args.perception_range is not None and not args.perception_range > 0:
        raise errors.UserError(f"--perception-range {args.perception_range}: give a positive number of cells, or leave "
                               "it out for no range")  # fmt: skip
    if args.resets < 100:
        raise errors.UserError(f"--resets {args.resets}: give at least 100 starts per split")
    presets.check_seeds(args.seed)
    if args.out is not None:  # before the minutes of measuring
        if args.out.exists() and not args.out.is_dir():
            raise errors.UserError(f"--out {args.out} is a file, not a folder; choose another --out")
        taken = [name for name in ("foresight.md", "foresight.json") if (args.out / name).exists()]
        if taken and not args.overwrite:
            raise errors.UserError(f"{args.out} already holds {', '.join(taken)}; pass --overwrite to replace them, or "
                                   "choose another --out")  # fmt: skip
    t0 = time.time()
    data = {}
    for i, split in enumerate(("train", "test")):
        env, params = envs.make("GridNav-v0", setup=args.setup, split=split, layout=args.layout, training=False,
                                priors=args.priors)  # fmt: skip
        data[split] = collect(env, params, args.resets, jax.random.fold_in(jax.random.PRNGKey(args.seed), i),
                              args.perception_range)  # fmt: skip
    results = {label: foresight_bound(data["train"], data["test"], label, args.seed)
               for label in ("turn", "bearing")}  # fmt: skip
    md = markdown(args, results, time.time() - t0)
    print(md)
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "foresight.md").write_text(md)
        rundir.write_json(args.out / "foresight.json", {"args": rundir.jsonable(dataclasses.asdict(args)), "results": results})
    return results


def cli(argv=None) -> dict:
    return errors.run_cli(Args, main, argv)


if __name__ == "__main__":
    cli(sys.argv[1:])
