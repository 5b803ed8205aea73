"""Run folders: config, metrics files, orbax checkpoints, reports and plots.

A run folder holds:
  run.json            what was run (method, preset, seed, config, schedule)
  metrics.jsonl/.csv  one row per update
  validation.jsonl    one row per validation (after each chunk)
  checkpoints/        orbax checkpoints of the whole training state (latest few)
  best/               the agent with the best validation SR (model selection)
  results_<split>.json/.md, learning_curve.png
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shutil
import sys
from pathlib import Path

import jax
import numpy as np

from experiments.tables import markdown_table, write_csv

RUN_FILE = "run.json"


class UserError(Exception):
    """A problem with what the user asked for: printed as one line, exit status 2."""


def fail(message: str, status: int = 2) -> None:
    print(f"error: {message}", file=sys.stderr)
    raise SystemExit(status)


def run_cli(args_class, main, argv=None):
    """A CLI's body: parse `argv` into `args_class` with tyro and run `main`; what the user
    asked wrongly (UserError, ValueError) is one line on stderr and exit status 2."""
    import tyro

    args = tyro.cli(args_class, args=argv)
    try:
        return main(args)
    except (UserError, ValueError) as e:
        fail(str(e))


def is_run(path: Path) -> bool:
    return (path / RUN_FILE).is_file()


def prepare_run_dir(path: Path, resume: bool, overwrite: bool, marker: str = RUN_FILE, kind: str = "run") -> None:
    """Create a fresh output folder, or check the one to resume. Never overwrites a user's
    folder silently: only a folder holding `marker` (what this program writes first, e.g.
    run.json or sweep.json) is ever deleted, and only with --overwrite."""
    if resume and overwrite:
        raise UserError("--resume and --overwrite exclude each other")
    if resume:
        if not (path / marker).is_file():
            raise UserError(f"{path} is not a {kind} folder (no {marker}); nothing to resume")
        return
    if path.exists() and any(path.iterdir()):
        if not overwrite:
            hint = "use --resume to continue it or --overwrite to replace it" if kind == "run" else (
                "use --overwrite to replace it or choose another --out")
            raise UserError(f"{path} already exists and is not empty; {hint}")
        if not (path / marker).is_file():
            raise UserError(f"{path} is not a {kind} folder (no {marker}); refusing to delete it, choose another --out")
        shutil.rmtree(path)
    path.mkdir(parents=True, exist_ok=True)


def write_started_args(path: Path, args, keep: tuple[str, ...]) -> None:
    """Save a CLI's arguments (a dataclass) for `resumed_args`; the fields in `keep` and
    resume/overwrite are this invocation's own and are not saved."""
    skip = ("resume", "overwrite", *keep)
    write_json(path, {k: v for k, v in dataclasses.asdict(args).items() if k not in skip})


def resumed_args(args, marker: str, kind: str, keep: tuple[str, ...]):
    """The arguments a run folder `args.out` was started with (`write_started_args` wrote
    them to `marker`), for --resume: a value given now that differs from them is refused
    in one line (a flag at its default cannot be told from one not given and is ignored);
    the fields in `keep` are taken from `args`."""
    prepare_run_dir(args.out, resume=True, overwrite=args.overwrite, marker=marker, kind=kind)
    saved = json.loads((args.out / marker).read_text())
    saved = {k: tuple(v) if isinstance(v, list) else v for k, v in saved.items() if k != "out"}
    defaults = type(args)()
    clash = [f"--{k.replace('_', '-')} {getattr(args, k)} (started with {v})" for k, v in saved.items()
             if jsonable(getattr(args, k)) not in (jsonable(getattr(defaults, k)), jsonable(v))]  # fmt: skip
    if clash:
        raise UserError(f"--resume continues {args.out} with the arguments it was started with; drop {', '.join(clash)}")
    return dataclasses.replace(type(args)(**{**saved, "out": args.out}), resume=True,
                               **{k: getattr(args, k) for k in keep})  # fmt: skip


def write_run_info(path: Path, info: dict) -> None:
    write_json(path / RUN_FILE, info)


def read_run_info(path: Path) -> dict:
    if not is_run(path):
        raise UserError(f"{path} is not a run folder (no {RUN_FILE}); pass the --out folder of experiments.train")
    return json.loads((path / RUN_FILE).read_text())


# ---------------------------------------------------------------------- JSON
def jsonable(x):
    """`x` as plain JSON values: dataclasses as dicts, tuples as lists, numpy scalars and
    arrays as Python numbers and lists, paths as strings, and every NaN or infinity as None
    (strict JSON has no NaN: an empty L>=5 bucket is written null)."""
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        x = dataclasses.asdict(x)
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, Path):
        return str(x)
    if x is None or isinstance(x, (str, int, bool)):
        return x
    raise TypeError(f"not JSON serialisable: {type(x)}")


def to_json(x, indent: int | None = None) -> str:
    """Strict JSON text of `x` (see `jsonable`): NaN is written null, never NaN."""
    return json.dumps(jsonable(x), indent=indent, allow_nan=False)


def write_json(path: Path, x) -> None:
    """`x` as strict, indented JSON (NaN as null), written atomically (a killed program
    leaves the old file or the new one, never half of one)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(to_json(x, indent=2))
    os.replace(tmp, path)


# ---------------------------------------------------------------------- metrics files
def metric_rows(metrics: dict, first_update: int, previous: dict | None = None) -> list[dict]:
    """Per-update rows from stacked chunk metrics ({name: [n]}), with running totals:
    `episodes` (ended), `frames` (useful: entering the loss) and `stepped_frames`
    (environment steps), continued from `previous` (the last row written, on resume)."""
    arrays = {k: np.asarray(v) for k, v in metrics.items()}
    n = len(next(iter(arrays.values())))
    previous = previous or {}
    episodes = float(previous.get("episodes", 0.0))
    frames = float(previous.get("frames", 0.0))
    stepped = float(previous.get("stepped_frames", 0.0))
    rows = []
    for i in range(n):
        episodes += float(arrays["charts/episodes"][i])
        frames += float(arrays["frames/useful"][i])
        stepped += float(arrays["frames/stepped"][i])
        row = {"update": first_update + i + 1, "episodes": episodes, "frames": frames, "stepped_frames": stepped}
        row.update({k: float(v[i]) for k, v in arrays.items()})
        rows.append(row)
    return rows


def append_rows(path: Path, rows: list[dict]) -> None:
    """Append rows to `path`.jsonl (strict JSON, NaN as null) and `path`.csv."""
    with open(path.with_suffix(".jsonl"), "a") as f:
        for row in rows:
            f.write(to_json(row) + "\n")
    write_csv(path.with_suffix(".csv"), rows, append=True)


def read_rows(path: Path) -> list[dict]:
    path = path.with_suffix(".jsonl")
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def truncate_rows(path: Path, last_update: int) -> None:
    """Drop rows after `last_update` (written after the checkpoint a resume starts from)."""
    rows = [r for r in read_rows(path) if r["update"] <= last_update]
    for suffix in (".jsonl", ".csv"):
        path.with_suffix(suffix).unlink(missing_ok=True)
    if rows:
        append_rows(path, rows)


def first_nonfinite(metrics: dict) -> int | None:
    """Index of the first update whose loss is NaN or inf, or None."""
    loss = np.asarray(metrics["losses/total_loss"])
    bad = np.flatnonzero(~np.isfinite(loss))
    return int(bad[0]) if len(bad) else None


# ---------------------------------------------------------------------- checkpoints
def checkpoint_manager(path: Path, keep: int):
    import orbax.checkpoint as ocp

    options = ocp.CheckpointManagerOptions(max_to_keep=keep, create=True)
    return ocp.CheckpointManager(path.absolute(), options=options)


def save(manager, step: int, tree) -> None:
    import orbax.checkpoint as ocp

    manager.save(step, args=ocp.args.StandardSave(tree), force=True)
    manager.wait_until_finished()


def drop_steps_after(manager, step: int) -> None:
    """Delete the checkpoints of steps after `step` (written after what a resume starts from)."""
    for s in manager.all_steps():
        if s > step:
            manager.delete(s)


def restore(manager, step: int, like):
    """The checkpoint of `step`, shaped as `like` and placed where `like`'s arrays are
    (numpy leaves: on the first local device), not where the saving process had them:
    without a sharding orbax restores the saved one, so a sweep's checkpoint of seeds
    spread over 2 devices came back spread over them in any reader, which then ran
    cross-device collectives it never asked for (and on the CPU these could time out:
    "Termination timeout for all reduce") and failed in a process with 1 device."""
    import orbax.checkpoint as ocp

    first = jax.sharding.SingleDeviceSharding(jax.local_devices()[0])
    abstract = jax.tree.map(lambda x: jax.ShapeDtypeStruct(np.shape(x), x.dtype, sharding=getattr(x, "sharding", first)),
                            like)  # fmt: skip
    return manager.restore(step, args=ocp.args.StandardRestore(abstract))


# ---------------------------------------------------------------------- reports
def results_markdown(results: dict, title: str, level: int = 1) -> str:
    cols = ("SPL", "SR", "SPL>=5", "SR>=5")
    rows = [[room, *(_fmt(m[c]) for c in cols), m["episodes"]] for room, m in results.items()]
    return "#" * level + f" {title}\n\n" + markdown_table(rows, ["rooms", *cols, "episodes"]) + "\n"


def _fmt(x: float) -> str:
    return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.2f}"


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
