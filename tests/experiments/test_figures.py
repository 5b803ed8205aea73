"""experiments.reporting.figures: a learning curve is written without touching matplotlib's
global state."""

import sys

import numpy as np

from experiments.reporting import figures


def test_learning_curve_png_leaves_matplotlib_global_state_alone(tmp_path, monkeypatch):
    import matplotlib

    def no_global_backend(*args, **kwargs):
        raise AssertionError("matplotlib.use called: the global backend must be left alone")

    monkeypatch.setattr(matplotlib, "use", no_global_backend)
    had_pyplot = "matplotlib.pyplot" in sys.modules
    x = np.arange(1, 6)
    figures.learning_curve_png(
        tmp_path / "c.png", {"a": (x, x / 10.0), "b": (x, np.stack([x, x + 1]) / 10.0)}, val_points=[(2, 0.1), (4, 0.3)]
    )
    assert (tmp_path / "c.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert ("matplotlib.pyplot" in sys.modules) == had_pyplot
