"""Studies whose sweep folders (without checkpoints) are kept as docs/data/*.tar.xz: unpack one
as experiments.compare reads a sweep."""

from __future__ import annotations

import json
import tarfile
from pathlib import Path, PurePosixPath

from experiments import rundir

DATA = Path(__file__).resolve().parents[1] / "docs" / "data"


ARCHIVES = sorted(p.name for p in DATA.glob("*.tar.xz"))


def read_archive_json(archive: str) -> dict[str, dict]:
    """{member name: parsed JSON} of every sweep.json, tune.json and run.json in
    docs/data/`archive`, read without extracting anything else."""
    with tarfile.open(DATA / archive) as tar:
        return {
            m.name: json.load(tar.extractfile(m))
            for m in tar.getmembers()
            if m.isfile() and PurePosixPath(m.name).name in ("sweep.json", "tune.json", "run.json")
        }


def extract(archive: str, folder: Path) -> None:
    """Unpack docs/data/`archive` into `folder`."""
    with tarfile.open(DATA / archive) as tar:
        # The "data" filter (no links out, no absolute paths) is in Python 3.11.4 and later.
        tar.extractall(folder, **({"filter": "data"} if hasattr(tarfile, "data_filter") else {}))


def unpack(archive: str, folder: Path, methods) -> Path:
    """Unpack docs/data/`archive` into `folder`; returns the sweep folder, checked to hold `methods` in that order."""
    extract(archive, folder)
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
    return (
        f"| {b} - {a} | {sr['mean']:.1f} ± {sr['std']:.1f} | {interval(pair['SR'])} | {interval(pair['SPL'])} | "
        f"{poi[0]:.2f} [{poi[1]:.2f}, {poi[2]:.2f}] | {r['p_holm']:.3f} | {r['mde']:.1f} |"
    )


def tune_report(archive: str, folder: Path) -> dict:
    """What `experiments.tune`'s report computes from a tune folder kept as docs/data/`archive`
    (no checkpoints): each method's chosen point, the grid's rows, and the arms paired each
    at its own chosen point ("best vs best")."""
    from experiments import tune
    from experiments.reporting import report, tuning

    extract(archive, folder)
    root = folder / "tune"
    args = rundir.args_from_saved(tune.Args, rundir.read_json(root / "tune.json"), out=root)
    table = tune.arms(args, tune.parse_grid(args.grid))
    results = {
        a: rundir.read_json(root / "sweep" / "methods" / a / "results.json")["results"]
        for by_point in table.values()
        for a in by_point.values()
    }
    chosen = {m: tuning.choose({p: results[a] for p, a in by_point.items()}) for m, by_point in table.items()}
    _, grid_rows = tuning.grid_table(table, results, chosen)
    best = {m: results[table[m][chosen[m]]] for m in args.methods}  # as tuning.tune_report pairs them
    _, best_vs_best = report.paired_report(best, tuning.pairs_of(args.methods), ["SR", "SPL"])
    return {"chosen": chosen, "grid_rows": grid_rows, "best_vs_best": best_vs_best, "table": table, "results": results}


def grid_line(row: dict) -> str:
    """The docs' row of one method at one grid point (validation SR, test SR and SPL)."""
    from experiments.reporting import stats

    val, sr, spl = (stats.summary(row[k]) for k in ("val_SR", "SR", "SPL"))
    return (
        f"| {row['method']} | {row['point'].split('=')[1]} | {val['mean']:.1f} ± {val['std']:.1f} | "
        f"{sr['mean']:.1f} ± {sr['std']:.1f} | {spl['mean']:.1f} ± {spl['std']:.1f} | "
        + ("**chosen** |" if row["chosen"] else "|")
    )


def best_vs_best_line(name: str, pair: dict) -> str:
    """The docs' row of one best-vs-best pair: SR and SPL intervals, IQM of B, P(B > A),
    Holm's p of SR / SPL, the MDE of SR."""
    r, spl_r = pair["robust"]["SR"], pair["robust"]["SPL"]
    poi, iqm = r["probability_of_improvement"], r["iqm_b"]
    return (
        f"| {name} | {interval(pair['SR'])} | {interval(pair['SPL'])} | {iqm[0]:.1f} [{iqm[1]:.1f}, {iqm[2]:.1f}] | "
        f"{poi[0]:.2f} [{poi[1]:.2f}, {poi[2]:.2f}] | {r['p_holm']:.3f} / {spl_r['p_holm']:.3f} | {r['mde']:.1f} |"
    )


def probe_fit_row(r: dict) -> str:
    """The docs' row of one seed of `experiments.probe`'s data: the share of sub-goals in the
    first fifth of the episode, then R^2 of the online f_w, the category mean, s_0, ridge on
    [s_0 : g] and the offline f_w."""
    f, sub = r["items"]["fit"], r["items"]["subgoal"]
    cells = [f"{100 * sub['shares'][0]:.0f}%"] + [
        f"{f[k]:.2f}"
        for k in (
            "r2_over_mean",
            "category_r2_over_mean",
            "identity_r2_over_mean",
            "ridge_r2_over_mean",
            "offline_r2_over_mean",
        )
    ]
    return f"| {r['seed']} | " + " | ".join(cells) + " |"
