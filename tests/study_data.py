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


def tune_report(archive: str, folder: Path) -> dict:
    """What `experiments.tune`'s report chooses from a tune folder kept as docs/data/`archive`
    (no checkpoints): each method's chosen point, with the grid and its arms' results (the
    grid's and the pairs' figures are generated blocks: tests/experiments/test_regenerate.py)."""
    from experiments import tune
    from experiments.reporting import tuning

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
    return {"chosen": chosen, "table": table, "results": results}
