"""Learning-curve figures (matplotlib's object API on an Agg canvas)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def learning_curve_png(path: Path, curves: dict, ylabel: str = "training success rate", val_points=None) -> None:
    """curves: {label: (x [n], y [n]) or (x [n], y [seeds, n])}; bands over seeds.

    Drawn with matplotlib's object API on an Agg canvas (as envs/render.py): matplotlib's
    global backend and pyplot's state are left alone."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 4))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for label, (x, y) in curves.items():
        y = np.atleast_2d(np.asarray(y, float))
        mean, std = y.mean(0), y.std(0)
        ax.plot(x, mean, label=label)
        if y.shape[0] > 1:
            ax.fill_between(x, mean - std, mean + std, alpha=0.25)
    if val_points:
        vx, vy = zip(*val_points)
        ax.plot(vx, vy, "o--", label="validation SR", color="black", markersize=4)
    ax.set_xlabel("updates")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def smooth(y, window: int = 20):
    """Trailing moving average (same length)."""
    y = np.asarray(y, float)
    out = np.empty_like(y)
    csum = np.cumsum(np.insert(y, 0, 0.0, axis=-1), axis=-1)
    for i in range(y.shape[-1]):
        lo = max(0, i + 1 - window)
        out[..., i] = (csum[..., i + 1] - csum[..., lo]) / (i + 1 - lo)
    return out
