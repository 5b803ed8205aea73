"""Experiment tracking beside the CSV: `train --track tensorboard` or `--track wandb`.

A tracker gets the rows the run folder's files get, as they are written: each update's
metrics (metrics.csv) and each validation (progress.json's, its columns prefixed
`validation/`), keyed by the update. Both backends are optional extras (`pip install
"foresit_jax[track]"`); asking for one that is not installed is a one-line error before
any training.

- `tensorboard` writes event files into `<run>/tensorboard` (tensorboardX):
  `tensorboard --logdir runs/x/tensorboard`.
- `wandb` logs to Weights & Biases; it works without a network in offline mode
  (`WANDB_MODE=offline`, the default when no `WANDB_API_KEY` is set), writing into
  `<run>/wandb` for a later `wandb sync`. A resumed run continues the same wandb run (its
  id is a hash of the folder's path).
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
from pathlib import Path

from experiments.errors import UserError

TRACKERS = ("none", "tensorboard", "wandb")
_PACKAGE = {"tensorboard": "tensorboardX", "wandb": "wandb"}


def check(kind: str) -> None:
    """One line, before any training, for an unknown tracker or a missing package."""
    if kind not in TRACKERS:
        raise UserError(f"--track must be one of {', '.join(TRACKERS)}, got {kind!r}")
    if kind != "none" and importlib.util.find_spec(_PACKAGE[kind]) is None:
        raise UserError(f"--track {kind} needs the {_PACKAGE[kind]} package: pip install 'foresit_jax[track]'")


class Tracker:
    """No tracking: every call does nothing."""

    def log(self, rows: list[dict], prefix: str = "") -> None:
        pass

    def close(self) -> None:
        pass


class TensorBoard(Tracker):
    def __init__(self, folder: Path):
        from tensorboardX import SummaryWriter

        self.writer = SummaryWriter(logdir=str(folder))

    def log(self, rows: list[dict], prefix: str = "") -> None:
        for row in rows:
            for name, value in row.items():
                if name != "update" and isinstance(value, (int, float)) and not isinstance(value, bool):
                    self.writer.add_scalar(prefix + name, value, global_step=int(row["update"]))
        self.writer.flush()

    def close(self) -> None:
        self.writer.close()


class WandB(Tracker):
    def __init__(self, folder: Path, run_id: str, name: str, config: dict):
        import wandb

        folder.mkdir(parents=True, exist_ok=True)
        mode = os.environ.get("WANDB_MODE") or ("online" if os.environ.get("WANDB_API_KEY") else "offline")
        self.run = wandb.init(
            project=os.environ.get("WANDB_PROJECT", "foresit_jax"),
            name=name,
            id=run_id,
            resume="allow",
            dir=str(folder),
            mode=mode,
            config=config,
        )

    def log(self, rows: list[dict], prefix: str = "") -> None:
        for row in rows:
            self.run.log({prefix + k: v for k, v in row.items() if k != "update"}, step=int(row["update"]))

    def close(self) -> None:
        self.run.finish()


def make(kind: str, out: Path, name: str, config: dict) -> Tracker:
    """The tracker of the run folder `out`, named `name`, of the Config `config` (as JSON)."""
    check(kind)
    if kind == "tensorboard":
        return TensorBoard(out / "tensorboard")
    if kind == "wandb":
        run_id = hashlib.sha256(str(Path(out).resolve()).encode()).hexdigest()[:16]  # the same on resume
        return WandB(out / "wandb", run_id, name, config)
    return Tracker()
