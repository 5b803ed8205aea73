"""Studies whose sweep folders (without checkpoints) are kept as docs/data/*.tar.xz: unpack one
as experiments.compare reads a sweep."""

from __future__ import annotations

import tarfile
from pathlib import Path

from experiments import runs

DATA = Path(__file__).resolve().parents[1] / "docs" / "data"


def unpack(archive: str, folder: Path, methods) -> Path:
    """Unpack docs/data/`archive` into `folder`; returns the sweep folder, checked to hold `methods` in that order."""
    with tarfile.open(DATA / archive) as tar:
        # The "data" filter (no links out, no absolute paths) is in Python 3.11.4 and later.
        tar.extractall(folder, **({"filter": "data"} if hasattr(tarfile, "data_filter") else {}))
    (root,) = [p for p in folder.iterdir() if p.is_dir()]
    assert runs.read_json(root / "sweep.json")["methods"] == list(methods)
    return root
