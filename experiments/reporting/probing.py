"""The report of the imagination probes (`experiments.running.probe_runs` runs them over trained
models): test SR under each condition of i_tau (`CONDITIONS`), f_w against its targets on
held-out items, f_w's training options replayed (`FIT_OPTIONS`), where the sub-goal falls,
as Markdown (`markdown`)."""

from __future__ import annotations

import numpy as np

from experiments.reporting import stats
from experiments.reporting.tables import markdown_table

CONDITIONS = ("trained", "noise off", "untrained f_w", "shuffled", "shuffled, noise off", "sampled actions")


# f_w's training options replayed by --fit-options: the run's own first, then one change
# each (Config fields: imagination_optimizer, imagination_lr, imagination_epochs, buffer_size,
# imagination_batch; and `KEEP_STATE`, the replay's own: one optimiser state kept across the
# flushes instead of a fresh one each, which training does not offer).
FIT_OPTIONS = {
    "as trained": {},
    "epochs 1": {"imagination_epochs": 1},
    "epochs 20": {"imagination_epochs": 20},
    "lr 3e-4": {"imagination_lr": 3e-4},
    "lr 3e-3": {"imagination_lr": 3e-3},
    "sgd, lr 1e-2 (Algorithm 1)": {"imagination_optimizer": "sgd", "imagination_lr": 1e-2},
    "M 8": {"buffer_size": 8},
    "M 128": {"buffer_size": 128},
    "batch 8": {"imagination_batch": 8},
    "batch 8, lr 3e-3": {"imagination_batch": 8, "imagination_lr": 3e-3},
    "state kept": {"keep_optimizer_state": True},
    "state kept, lr 3e-4": {"keep_optimizer_state": True, "imagination_lr": 3e-4},
}
KEEP_STATE = "keep_optimizer_state"


def _fmt(x, digits: int = 1) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def markdown(report: dict, episodes: int, windows: int, level: int = 1) -> str:
    h = "#" * level
    md = [
        f"{h} Imagination probes\n\nTest SR (%) of each seed's selected model on the same {episodes} test episodes "
        "per room type under each condition; each condition paired with `trained` over the seeds "
        "(difference [95% interval]).\n"
    ]
    for method, per_seed in report.items():
        seeds = [r["seed"] for r in per_seed]
        md.append(f"{h}# {method} (seeds {', '.join(map(str, seeds))})\n")
        conditions = [c for c in CONDITIONS if c in per_seed[0]["sr"]]
        rows = []
        for c in conditions:
            values = [r["sr"][c] for r in per_seed]
            s = stats.summary(values)
            pair = stats.paired([r["sr"]["trained"] for r in per_seed], values) if c != "trained" else None
            diff = "" if pair is None else f"{pair['diff']:+.1f} [{_fmt(pair['ci_low'])}, {_fmt(pair['ci_high'])}]"
            rows.append([c, " / ".join(_fmt(v) for v in values), f"{_fmt(s['mean'])} ± {_fmt(s['std'])}", diff])
        md.append(markdown_table(rows, ["condition", "SR per seed", "mean ± std", "minus trained"]) + "\n")
        fits = [r["items"].get("fit") for r in per_seed]
        if all(fits):
            cells = []
            for r in per_seed:
                f, g = r["items"]["fit"], r["items"]["signal"]
                cells.append(
                    [
                        r["seed"],
                        f["items"],
                        f"{f['smooth_l1']:.4f}",
                        _fmt(f["r2_over_mean"], 2),
                        _fmt(f["category_r2_over_mean"], 2),
                        _fmt(f.get("identity_r2_over_mean"), 2),
                        _fmt(f.get("ridge_r2_over_mean"), 2),
                        _fmt(f.get("offline_r2_over_mean"), 2),
                        _fmt(f["r2_over_category"], 2),
                        f"{g['signal_variance']:.3f} / {g['noise_variance']:.3f} ({g['signal_share']:.2f})",
                    ]
                )
            md.append(
                "f_w on held-out sub-goal items (odd items; the baselines fit on the even ones), R^2 over the "
                "targets' mean: the online f_w; the target category's mean; s_0 itself (f_w's input); ridge "
                "regression on [s_0 : g]; f_w's architecture trained offline on the even items (full batch, "
                "Adam, early-stopped on a fifth of them); then f_w's R^2 over the category mean; i_tau's "
                "variance: f_w's outputs across episodes / the noise's (signal share).\n"
            )
            md.append(
                markdown_table(
                    cells,
                    [
                        "seed",
                        "items",
                        "smooth-L1",
                        "R^2 f_w",
                        "category mean",
                        "s_0",
                        "ridge",
                        "offline f_w",
                        "R^2 f_w over category",
                        "signal / noise variance",
                    ],
                )
                + "\n"
            )
        if all(r["items"].get("fit_options") for r in per_seed):
            names = list(per_seed[0]["items"]["fit_options"])
            cells = [
                [
                    r["seed"],
                    *(_fmt(r["items"]["fit_options"][n], 2) for n in names),
                    _fmt(r["items"]["fit"]["offline_r2_over_mean"], 2),
                ]
                for r in per_seed
            ]
            md.append(
                "f_w's online training replayed on the fit items at the trained encoder, from the run's initial "
                "f_w, one option changed at a time (`--fit-options`): R^2 over the mean on the held-out items, "
                "beside the offline f_w's.\n"
            )
            md.append(markdown_table(cells, ["seed", *names, "offline f_w"]) + "\n")
        sub = [r["items"]["subgoal"] for r in per_seed]
        edges = sub[0]["edges"]
        bins = [f"{edges[i]:.1f}-{edges[i + 1]:.1f}" for i in range(len(edges) - 1)]
        cells = [
            [r["seed"], s["episodes"], *(_fmt(100 * x, 0) for x in s["shares"]), _fmt(100 * s["at_done"], 0)]
            for r, s in zip(per_seed, sub)
        ]
        md.append(
            f"Where the sub-goal falls in its successful episode ({windows} training windows): t*/T in % of "
            "episodes, and t* = T (the Done step's own state).\n"
        )
        md.append(markdown_table(cells, ["seed", "episodes", *[f"t*/T {b}" for b in bins], "at Done"]) + "\n")
    return "\n".join(md)
