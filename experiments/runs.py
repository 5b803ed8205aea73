"""Run folders: config, metrics files, orbax checkpoints, reports and plots.

A run folder holds:
  run.json            what was run (method, preset, seed, config, schedule)
  metrics.jsonl/.csv  one row per update
  validation.jsonl    one row per validation (after each chunk)
  checkpoints/        orbax checkpoints of the whole training state (latest few)
  best/               the agent with the best validation SR (model selection)
  results_<split>.json/.md, learning_curve.png
  .lock               held (an OS lock, `claim`) by the one process writing the folder

Every checkpoint gets a checksum of its files at save (`save`), checked before it is
restored (`restore`): a corrupt or truncated one is one line naming it, and a resume falls
back to the newest intact one (`intact_step`).
"""

from __future__ import annotations

import dataclasses
import errno
import fcntl
import hashlib
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
    except OSError as e:  # disk full, read-only, not a directory: one line, not a traceback
        if e.errno not in _USER_ERRNOS:
            raise
        fail(os_message(e), status=1 if e.errno in (errno.ENOSPC, errno.EDQUOT) else 2)


# What the user's disk or paths did, not a bug: reported in one line.
_USER_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.ENOTDIR, errno.EISDIR,
                errno.EEXIST, errno.ENOENT}  # fmt: skip


def os_message(e: OSError) -> str:
    where = f"{e.filename}: " if e.filename else ""
    return f"{where}{e.strerror or e}" + (" (free some space, then continue with --resume)"
                                          if e.errno in (errno.ENOSPC, errno.EDQUOT) else "")  # fmt: skip


# ---------------------------------------------------------------------- one writer per folder
LOCK_FILE = ".lock"
_held: dict[Path, int] = {}  # folder -> file descriptor of its lock, for this process's life


def claim(path: Path) -> None:
    """Make this process the one writer of the folder `path` (created if missing): an
    exclusive OS lock (flock) on `path`/.lock, held until the process exits (a crash
    releases it; the file left behind locks nothing). Another process holding it is a
    UserError naming its pid; claiming a folder this process holds is a no-op."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UserError(f"{path} is a file, not a folder; choose another --out")
    path.mkdir(parents=True, exist_ok=True)
    key = path.resolve()
    if key in _held:
        return
    fd = os.open(path / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.read(fd, 64).decode(errors="replace").strip() or "unknown"
        os.close(fd)
        raise UserError(f"{path} is being written by another process (pid {holder}); wait for it to finish, "
                        "or choose another --out") from None  # fmt: skip
    os.ftruncate(fd, 0)
    os.write(fd, str(os.getpid()).encode())
    _held[key] = fd


def _contents(path: Path) -> list[Path]:
    return [p for p in path.iterdir() if p.name != LOCK_FILE]


def is_run(path: Path) -> bool:
    return (path / RUN_FILE).is_file()


def prepare_run_dir(path: Path, resume: bool, overwrite: bool, marker: str = RUN_FILE, kind: str = "run") -> None:
    """Create a fresh output folder, or check the one to resume, after claiming it (`claim`:
    one writer per folder). Never overwrites a user's folder silently: only a folder
    holding `marker` (what this program writes first, e.g. run.json or sweep.json) is ever
    emptied, and only with --overwrite."""
    if resume and overwrite:
        raise UserError("--resume and --overwrite exclude each other")
    if resume:
        if not (path / marker).is_file():
            raise UserError(f"{path} is not a {kind} folder (no {marker}); nothing to resume")
        claim(path)
        return
    if path.exists() and path.is_dir() and _contents(path):
        if (path / marker).is_file():
            claim(path)  # a folder of ours that another process is writing: say so, with its pid
        if not overwrite:
            hint = "use --resume to continue it or --overwrite to replace it" if kind == "run" else (
                "use --overwrite to replace it or choose another --out")
            raise UserError(f"{path} already exists and is not empty; {hint}")
        if not (path / marker).is_file():
            raise UserError(f"{path} is not a {kind} folder (no {marker}); refusing to delete it, choose another --out")
    claim(path)  # before looking again: a process that started at the same instant is refused here
    if _contents(path):
        if not overwrite:
            raise UserError(f"{path} was written by another process a moment ago; choose another --out")
        for p in _contents(path):
            shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink()


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
    started = args_from_saved(type(args), read_json(args.out / marker), out=args.out)
    defaults = type(args)()
    clash = []
    for f in dataclasses.fields(args):
        if f.name in (*keep, "resume", "overwrite", "out"):
            continue
        mine, theirs, default = (getattr(x, f.name) for x in (args, started, defaults))
        if dataclasses.is_dataclass(mine):  # nested flags (e.g. Config fields): each on its own
            clash += [f"--{k.replace('_', '-')} {v} (started with {getattr(theirs, k)})"
                      for k, v in dataclasses.asdict(mine).items()
                      if v is not None and jsonable(v) != jsonable(getattr(theirs, k))]  # fmt: skip
        elif jsonable(mine) not in (jsonable(default), jsonable(theirs)):
            clash.append(f"--{f.name.replace('_', '-')} {mine} (started with {theirs})")
    if clash:
        raise UserError(f"--resume continues {args.out} with the arguments it was started with; drop {', '.join(clash)}")
    return dataclasses.replace(started, resume=True, **{k: getattr(args, k) for k in keep})


def args_from_saved(cls, saved: dict, **given):
    """A CLI's arguments (`cls`, a dataclass) from what `write_started_args` saved: JSON
    lists back to tuples, nested dataclasses rebuilt (a field saved before it existed
    takes its default); `given` overrides."""
    defaults, values = cls(), {}
    for f in dataclasses.fields(cls):
        if f.name not in saved:
            continue
        value, default = saved[f.name], getattr(defaults, f.name)
        if dataclasses.is_dataclass(default) and isinstance(value, dict):
            value = type(default)(**{k: tuple(v) if isinstance(v, list) else v for k, v in value.items()})
        values[f.name] = tuple(value) if isinstance(value, list) else value
    return cls(**{**values, **given})


def write_run_info(path: Path, info: dict) -> None:
    write_json(path / RUN_FILE, info)


def read_run_info(path: Path) -> dict:
    if not is_run(path):
        raise UserError(f"{path} is not a run folder (no {RUN_FILE}); pass the --out folder of experiments.train")
    return read_json(path / RUN_FILE)


def read_json(path: Path):
    """A JSON file this project wrote; a broken one is a UserError naming it."""
    try:
        return json.loads(Path(path).read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise UserError(f"{path} is not valid JSON ({e}); it was damaged after it was written") from None


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
    """Append rows to `path`.jsonl (strict JSON, NaN as null) and `path`.csv, in one write
    each (a kill can still cut the last line: `read_rows` drops a cut one)."""
    with open(path.with_suffix(".jsonl"), "a") as f:
        f.write("".join(to_json(row) + "\n" for row in rows))
    write_csv(path.with_suffix(".csv"), rows, append=True)


def read_rows(path: Path) -> list[dict]:
    """The rows of `path`.jsonl. A last line a kill cut short (no newline, not JSON) is
    dropped with a warning: it is rewritten when its updates run again. A broken line
    elsewhere is a UserError naming the file and line."""
    path = path.with_suffix(".jsonl")
    if not path.exists():
        return []
    text = path.read_text()
    lines = text.split("\n")
    rows = []
    for i, line in enumerate(lines):
        if not line.strip():
            continue
        try:
            rows.append(json.loads(line))
        except json.JSONDecodeError:
            if i == len(lines) - 1:  # the last line, with no newline after it: a cut append
                print(f"warning: {path}: dropped a partial last line (a write was cut short)", file=sys.stderr)
                break
            raise UserError(f"{path}: line {i + 1} is not valid JSON; it was damaged after it was written") from None
    return rows


def truncate_rows(path: Path, last_update: int) -> None:
    """Drop rows after `last_update` (written after the checkpoint a resume starts from)
    and a cut last line (`read_rows`); each file is replaced whole (written, then renamed:
    a kill leaves the old file or the new one)."""
    rows = [r for r in read_rows(path) if r["update"] <= last_update]
    for suffix in (".jsonl", ".csv"):
        target = path.with_suffix(suffix)
        if not rows:
            target.unlink(missing_ok=True)
            continue
        tmp = target.with_name(target.name + ".tmp")
        if suffix == ".jsonl":
            tmp.write_text("".join(to_json(row) + "\n" for row in rows))
        else:
            write_csv(tmp, rows)
        os.replace(tmp, target)


def finite_seeds(tree, num_seeds: int | None = None) -> np.ndarray:
    """Whether every float of `tree` (a training state: parameters, optimiser moments,
    f_w) is finite: a bool, or with `num_seeds` one per seed (leaves stacked over seeds).
    The loss is computed before each update, so a finite loss can still leave NaN
    weights behind (an infinite step, for one): this is checked before every save."""
    ok = np.ones(num_seeds or 1, bool)
    for leaf in jax.tree.leaves(tree):
        if not jax.dtypes.issubdtype(leaf.dtype, np.floating):
            continue
        ok &= np.isfinite(np.asarray(leaf)).reshape(len(ok), -1).all(1)
    return ok if num_seeds else ok[0]


# Divergence, short of NaN: bounds about 1000x past what quick training shows (its
# gradient norm stays below 4 and |loss| below 2; entropy, at most ln 6 = 1.79, above 0.3).
DIVERGENCE_BOUNDS = {"losses/grad_norm": 1e4, "losses/total_loss": 1e4}
COLLAPSED_ENTROPY = 1e-3


def divergence(metrics: dict) -> str | None:
    """A warning when a chunk's metrics ({name: [..., n]}) show divergence short of NaN:
    a loss or gradient norm beyond `DIVERGENCE_BOUNDS` (or infinite), or the policy's
    entropy below `COLLAPSED_ENTROPY` (deterministic: it no longer explores); None if not."""
    found = []
    for name, bound in DIVERGENCE_BOUNDS.items():
        x = np.abs(np.asarray(metrics.get(name, 0.0), float))
        if not (x <= bound).all():
            found.append(f"{name.split('/')[-1]} reached {np.nanmax(np.where(np.isnan(x), -np.inf, x)):.3g} (bound {bound:g})")
    entropy = np.asarray(metrics.get("losses/entropy", 1.0), float)
    if (entropy < COLLAPSED_ENTROPY).any():
        found.append(f"the policy's entropy fell to {np.nanmin(entropy):.3g} (collapsed below {COLLAPSED_ENTROPY:g})")
    return "training may be diverging: " + "; ".join(found) + " (a lower --learning-rate may help)" if found else None


# ---------------------------------------------------------------------- checkpoints
def checkpoint_manager(path: Path, keep: int):
    import orbax.checkpoint as ocp

    options = ocp.CheckpointManagerOptions(max_to_keep=keep, create=True)
    return ocp.CheckpointManager(path.absolute(), options=options)


CHECKSUM_FILE = "foresit_sha256.json"


class CorruptCheckpoint(UserError):
    """A checkpoint whose files are not those saved (or that orbax cannot read)."""


def step_dir(manager, step: int) -> Path:
    return Path(str(manager.directory)) / str(step)


def _digest(folder: Path) -> str:
    """SHA-256 over every file under `folder` (but the checksum file): names and bytes."""
    h = hashlib.sha256()
    for f in sorted(p for p in folder.rglob("*") if p.is_file() and p.name != CHECKSUM_FILE):
        h.update(str(f.relative_to(folder)).encode() + b"\0")
        with open(f, "rb") as stream:
            for block in iter(lambda: stream.read(1 << 20), b""):
                h.update(block)
        h.update(b"\0")
    return h.hexdigest()


def save(manager, step: int, tree) -> None:
    """Save `tree` as checkpoint `step` and record its checksum (`verify`). A disk too full
    for it is an OSError (ENOSPC) before orbax starts writing: orbax's failure in the
    middle of a write prints hundreds of lines from its storage threads."""
    import orbax.checkpoint as ocp

    folder = Path(str(manager.directory))
    need = sum(int(getattr(leaf, "nbytes", 0)) for leaf in jax.tree.leaves(tree))
    free = shutil.disk_usage(folder).free
    if free < need * 1.25 + (1 << 20):
        raise OSError(errno.ENOSPC, f"No space left on device for checkpoint {step} (about {need / 2**20:.1f} MB; "
                                    f"{free / 2**20:.1f} MB free)", str(folder))  # fmt: skip
    try:
        manager.save(step, args=ocp.args.StandardSave(tree), force=True)
        manager.wait_until_finished()
    except Exception as e:
        if "No space left on device" in str(e) or "os_error_code='28'" in str(e):
            raise OSError(errno.ENOSPC, f"No space left on device while writing checkpoint {step}", str(folder)) from None
        raise
    folder = step_dir(manager, step)
    write_json(folder / CHECKSUM_FILE, {"sha256": _digest(folder)})


def verify(manager, step: int) -> None:
    """Raise CorruptCheckpoint (one line naming it) when checkpoint `step`'s files are not
    those `save` wrote. A checkpoint without a checksum (saved before checksums were
    recorded) passes."""
    folder = step_dir(manager, step)
    recorded = folder / CHECKSUM_FILE
    if not recorded.is_file():
        return
    try:
        expected = json.loads(recorded.read_text())["sha256"]
    except (json.JSONDecodeError, KeyError, TypeError, UnicodeDecodeError):
        raise CorruptCheckpoint(f"checkpoint {folder} is damaged (its checksum file cannot be read)") from None
    if _digest(folder) != expected:
        raise CorruptCheckpoint(f"checkpoint {folder} is corrupt or truncated: its files no longer match the "
                                "checksum recorded when it was saved")  # fmt: skip


def intact_step(manager, at_most: int | None = None) -> tuple[int | None, list[str]]:
    """The newest checkpoint step (at most `at_most`) that `verify` passes, or None, and
    one line per newer one skipped as corrupt."""
    skipped = []
    for step in sorted(manager.all_steps(), reverse=True):
        if at_most is not None and step > at_most:
            continue
        try:
            verify(manager, step)
            return step, skipped
        except CorruptCheckpoint as e:
            skipped.append(str(e))
    return None, skipped


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

    verify(manager, step)
    first = jax.sharding.SingleDeviceSharding(jax.local_devices()[0])
    abstract = jax.tree.map(lambda x: jax.ShapeDtypeStruct(np.shape(x), x.dtype, sharding=getattr(x, "sharding", first)),
                            like)  # fmt: skip
    try:
        return manager.restore(step, args=ocp.args.StandardRestore(abstract))
    except Exception as e:  # orbax's (often multi-line) reason, as one line naming the checkpoint
        reason = " ".join(str(e).split())[:300]
        raise CorruptCheckpoint(f"cannot restore checkpoint {step_dir(manager, step)}: {type(e).__name__}: {reason}") from None


# ---------------------------------------------------------------------- reports
RESULT_COLUMNS = ("SPL", "SR", "SPL>=5", "SR>=5")  # Table 1's columns
HOUSE_COLUMNS = ("SPL>=10", "SR>=10", "SPL>=20", "SR>=20")  # and the houses' longer buckets (envs.metrics)


def results_markdown(results: dict, title: str, level: int = 1) -> str:
    """One row per room type (and overall); houses' results add their L >= 10, 20 columns."""
    first = next(iter(results.values()))
    cols = RESULT_COLUMNS + tuple(c for c in HOUSE_COLUMNS if c in first)
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
