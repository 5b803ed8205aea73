"""The foresight a layout family offers, the pure part (`experiments.foresight` measures it):
a logistic regression fitted on the first views of the train split's layouts predicts the
first turn and the target's bearing on the test split's; the gain of knowing the target
over the view alone, with a 95% interval over the test layouts (docs/foresight.md).
Tested on synthetic data with a planted relation and without one (tests/experiments/test_foresight.py)."""

from __future__ import annotations

from typing import Optional

import numpy as np

from envs import catalog as C
from envs.priors import RELATIONS
from experiments.reporting.tables import markdown_table

FEATURE_SETS = ("geometry", "view", "view + target")
TURNS = ("left", "right")
BEARINGS = ("ahead", "right", "behind", "left")
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
    scores = [
        np.mean([np.mean(model(c).fit(train_x[a], train_y[a]).predict(train_x[b]) == train_y[b]) for a, b in folds])
        for c in REGULARISATIONS
    ]
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
    out = {
        "train_samples": int(keep_train.sum()),
        "test_samples": int(keep_test.sum()),
        "test_groups": int(len(np.unique(test["group"][keep_test]))),
    }
    if not len(y_test) or not len(y_train):
        return out
    majority = np.bincount(y_train).argmax()
    out["majority"] = float(np.mean(y_test == majority))
    out["test_shares"] = (np.bincount(y_test) / len(y_test)).tolist()  # each label's share of the test rows
    correct = {}
    for name in FEATURE_SETS:
        predicted, out[f"C {name}"] = fit_and_score(
            train[name][keep_train], y_train, train["group"][keep_train], test[name][keep_test]
        )
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


# ---------------------------------------------------------------------- the features of first views
def within_range(
    sem: np.ndarray,
    depth: np.ndarray,
    perception_range: Optional[float],
    num_semantic: int,
    num_targets: int,
    structural: int,
) -> tuple[np.ndarray, int]:
    """A perception range emulated on views (sem, depth [N, 3, W]): the object categories
    (`structural` .. `structural + num_targets`) seen farther than `perception_range` cells
    become one extra class, `num_semantic` ("an object, unresolved"); walls, floor and
    furniture stay as they are. Returns (the views' classes, the number of classes); None
    leaves the views alone."""
    if perception_range is None:
        return sem, num_semantic
    far = (sem >= structural) & (sem < structural + num_targets) & (depth > perception_range)
    return np.where(far, num_semantic, sem), num_semantic + 1


def features(
    sem: np.ndarray,
    depth: np.ndarray,
    target: np.ndarray,
    num_semantic: int,
    num_targets: int,
    structural: int,
    unresolved: Optional[int] = None,
) -> dict[str, np.ndarray]:
    """The feature sets of first views: sem, depth [N, 3, W] (envs' `view`, or
    `within_range`'s, whose `unresolved` class reads as an object in the geometry), the
    target category [N] (ints, the setup's category index)."""
    n, width = sem.shape[0], sem.shape[-1]
    # Every object category (and an unresolved object) -> one "object" class; every
    # furniture kind (layouts with priors: classes after the categories) -> furniture.
    coarse = np.where(sem >= structural + num_targets, C.SEM_FURNITURE, np.minimum(sem, structural))
    if unresolved is not None:
        coarse = np.where(sem == unresolved, structural, coarse)
    geometry = np.concatenate(
        [np.eye(structural + 1)[coarse].reshape(n, -1), depth.reshape(n, -1) / max(float(depth.max()), 1e-9)], axis=1
    )
    half = width // 2
    sides = np.stack(
        [
            np.eye(num_semantic)[sem[..., :half]].any(axis=(1, 2)),
            np.eye(num_semantic)[sem[..., half:]].any(axis=(1, 2)),
        ],
        axis=1,
    ).reshape(n, -1)  # [N, 2 * classes]
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


# ---------------------------------------------------------------------- the report
def markdown(
    results: dict,
    seconds: float,
    setup: str,
    layout: str,
    priors: bool,
    resets: int,
    perception_range: Optional[float] = None,
) -> str:
    """The report of `foresight_bound`'s results for the turn and the bearing (a Markdown table)."""
    rows = []
    for label, r in results.items():
        if "gain" not in r:
            rows.append([label, r["train_samples"], r["test_samples"], *["n/a"] * 6])
            continue
        lo, hi = r["gain_ci"]
        rows.append(
            [
                label,
                r["train_samples"],
                f"{r['test_samples']} ({r['test_groups']} layouts)",
                *(f"{100 * r[k]:.1f}" for k in ("majority", *FEATURE_SETS)),
                f"{100 * r['gain']:+.1f} [{100 * lo:+.1f}, {100 * hi:+.1f}]",
            ]
        )
        for name, part in r.get("subsets", {}).items():
            if "gain" in part:
                lo, hi = part["gain_ci"]
                rows.append(
                    [
                        f"{label}, {name}",
                        "",
                        f"{part['samples']} ({100 * part['share']:.0f}%)",
                        "",
                        *(f"{100 * part[k]:.1f}" for k in FEATURE_SETS),
                        f"{100 * part['gain']:+.1f} [{100 * lo:+.1f}, {100 * hi:+.1f}]",
                    ]
                )
    shares = "; ".join(
        f"{label}: " + ", ".join(f"{name} {100 * share:.0f}%" for name, share in zip(names, r["test_shares"]))
        for (label, r), names in zip(results.items(), (TURNS, BEARINGS))
        if "test_shares" in r
    )
    family = f"{layout} layouts with priors" if priors else f"{layout} layouts"
    if perception_range is not None:
        family += f", objects resolved within {perception_range:g} cells (emulated on the view)"
    return (
        f"# Foresight: {setup} setup, {family}\n\n"
        f"{resets} starts per split; the starts whose first view does not show the target; fitted on the "
        "train layouts, accuracy (%) on the test layouts; the gain of the target over the view with its 95% "
        f"interval over the test layouts ({seconds:.0f} s).\n\n"
        + markdown_table(
            rows, ["predicts", "train starts", "test starts", "majority", *FEATURE_SETS, "gain from the target"]
        )
        + "\n"
        + (f"\nThe test starts' labels: {shares}.\n" if shares else "")
    )
