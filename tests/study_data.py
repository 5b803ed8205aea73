"""Studies whose sweep folders (without checkpoints) are kept as docs/data/*.tar.xz: unpack one
as experiments.compare reads a sweep."""

from __future__ import annotations

import tarfile
from pathlib import Path

from experiments.running import rundir

DATA = Path(__file__).resolve().parents[1] / "docs" / "data"


def unpack(archive: str, folder: Path, methods) -> Path:
    """Unpack docs/data/`archive` into `folder`; returns the sweep folder, checked to hold `methods` in that order."""
    with tarfile.open(DATA / archive) as tar:
        # The "data" filter (no links out, no absolute paths) is in Python 3.11.4 and later.
        tar.extractall(folder, **({"filter": "data"} if hasattr(tarfile, "data_filter") else {}))
    (root,) = [p for p in folder.iterdir() if p.is_dir()]
    assert rundir.read_json(root / "sweep.json")["methods"] == list(methods)
    return root


def signed(x: float) -> str:
    return f"{x:+.1f}".replace("+-", "-")


def interval(p: dict) -> str:
    """A `stats.paired` result as the docs write it: "+d.d [+lo, +hi]"."""
    return f"{signed(p['diff'])} [{signed(p['ci_low'])}, {signed(p['ci_high'])}]"


def pair_row(out: dict, results: dict, a: str, b: str) -> str:
    """The docs' row of the pair B - A of `experiments.compare.main`'s `out`: B's SR (mean ±
    std), the SR and SPL intervals, P(B > A), Holm's p and the MDE on SR."""
    from experiments.reporting import report, stats

    pair = out["pairs"][f"{b} - {a}"]
    r = pair["robust"]["SR"]
    poi, sr = r["probability_of_improvement"], stats.summary(report.values(results[b], "SR"))
    return (f"| {b} - {a} | {sr['mean']:.1f} ± {sr['std']:.1f} | {interval(pair['SR'])} | {interval(pair['SPL'])} | "
            f"{poi[0]:.2f} [{poi[1]:.2f}, {poi[2]:.2f}] | {r['p_holm']:.3f} | {r['mde']:.1f} |")
