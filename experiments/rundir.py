"""The run-folder format, in one module: what each file of a run or sweep folder is called and
holds, its reading and writing, one writer at a time, and the arguments a program started with.

A run folder (`train`'s, or one arm of a sweep: `experiments.running.run.Run`) holds

  run.json        what was run: the arm, its preset, Config and Schedule, the seeds, the
                  selection protocol; it reads alone (`RUN_FILE`, `read_run_info`)
  progress.json   the updates done; per seed its validations and its best model's SR and
                  update; per chunk the training SR of every update, diagnostics and counts;
                  the platform of each stretch of updates (`PROGRESS_FILE`, `read_progress`)
  checkpoints/    orbax checkpoints of {"states", "best"}, named by their update: every
                  seed's training state and the model selected on validation, stacked over
                  the seeds (`CHECKPOINTS`, `checkpoint_at`)
  results.json    at the end: per seed the test results of the selected and the last model,
                  its validations and its training curve (`RESULTS_FILE`, `read_results`);
                  an extended run keeps the one before as results_<n>_updates.json
                  (`kept_results`) and its program's report in report_<n>_updates/

and train adds metrics.jsonl/.csv (one row per update: `append_rows`, `read_rows`) and its
report. A sweep folder holds sweep.json (its arguments: `SWEEP_FILE`), one run folder per arm
(methods/<arm>/: `arm_folder`), and results_per_seed.json with its report; a tune's folder
holds tune.json and its sweep, a paper run's paper.json and one sweep per setup. Every folder a
program writes has a `.lock`, held (an OS lock, `claim`) by the one process writing it.

A leaf: it imports nothing of the project but `experiments.errors`, so the run machinery
(experiments/running) and the analysis that reads finished folders (experiments/reporting)
both read the format here (tests/structure/test_layering.py). A program's report (its tables,
figures, Markdown and the JSON beside them) is named where it is written.
"""

from __future__ import annotations

import csv
import dataclasses
import errno
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from experiments.errors import RunNotFound, UserError, given_flags, on_refusal, read_json, say_ignored  # noqa: F401 (rundir.read_json: a run folder's files read back)

try:  # POSIX: flock on the folder's .lock, which also names the holder's pid
    import fcntl
except ImportError:  # native Windows (jax runs there on the CPU): filelock's msvcrt lock
    fcntl = None

# ---------------------------------------------------------------------- the format
RUN_FILE = "run.json"
PROGRESS_FILE = "progress.json"
RESULTS_FILE = "results.json"
CHECKPOINTS = "checkpoints"
SWEEP_FILE = "sweep.json"
METHODS = "methods"
PER_SEED_FILE = "results_per_seed.json"
TUNE_FILE = "tune.json"  # a tune's folder: its arguments, and its sweep in sweep/
PAPER_FILE = "paper.json"  # a paper run's folder: its arguments, and one sweep per setup
FORMAT_NAMES = (
    RUN_FILE,
    PROGRESS_FILE,
    RESULTS_FILE,
    CHECKPOINTS,
    SWEEP_FILE,
    METHODS,
    PER_SEED_FILE,
    TUNE_FILE,
    PAPER_FILE,
)
# What every run.json, progress.json and results.json holds (a damaged one lacks some: `read_json`).
RUN_KEYS = ("config", "schedule")
PROGRESS_KEYS = ("done",)
RESULTS_KEYS = ("updates", "results")


def arm_folder(sweep: Path, arm: str) -> Path:
    """The run folder of the arm `arm` in the sweep folder `sweep`."""
    return Path(sweep) / METHODS / arm


def arm_folders(sweep: Path) -> list[Path]:
    """The run folders of a sweep folder's arms, in name order (none before one starts)."""
    folder = Path(sweep) / METHODS
    return sorted(p for p in folder.iterdir() if p.is_dir()) if folder.is_dir() else []


def is_sweep(path: Path) -> bool:
    return (Path(path) / SWEEP_FILE).is_file()


def in_sweep(folder: Path) -> bool:
    """Whether the run folder `folder` is an arm of a sweep (methods/<arm>/ of a sweep folder)."""
    folder = Path(folder)
    return folder.parent.name == METHODS and is_sweep(folder.parent.parent)


def checkpoint_at(folder: Path, update: int | None = None) -> Path:
    """A run folder's checkpoints/, or its checkpoint of update `update`."""
    path = Path(folder) / CHECKPOINTS
    return path if update is None else path / str(update)


def kept_results(updates: int) -> str:
    """The name an extended run keeps its results.json of `updates` updates under."""
    return f"results_{updates}_updates.json"


def kept_report(updates: int) -> str:
    """The folder an extended run keeps its program's report of `updates` updates in."""
    return f"report_{updates}_updates"


def read_results(folder: Path, required: bool = False) -> dict | None:
    """A run folder's results.json ({"updates", "results": one per seed, ...}), or None
    before the run has finished (`required`: a RunNotFound naming the file instead)."""
    path = Path(folder) / RESULTS_FILE
    if path.is_file():
        return read_json(path, RESULTS_KEYS)
    if required:
        raise RunNotFound(f"{folder} has not finished ({RESULTS_FILE} is not there); train it to the end first")
    return None


def read_progress(folder: Path) -> dict | None:
    """A run folder's progress.json, or None where it keeps none (not started, or assembled
    from other sweeps' seeds)."""
    path = Path(folder) / PROGRESS_FILE
    return read_json(path, PROGRESS_KEYS) if path.is_file() else None


def finished_seeds(folder: Path) -> list[int]:
    """The seeds a run folder has finished (none when it has not finished)."""
    done = read_results(folder)
    return [] if done is None else [r["seed"] for r in done["results"]]


def sweep_results(sweep: Path) -> dict[str, list[dict]]:
    """Every finished arm of the sweep folder `sweep`: its per-seed results (results.json's
    "results"), in name order; a UserError (one line) where it is no sweep folder or no arm
    has finished."""
    if not (Path(sweep) / METHODS).is_dir():
        check_path(Path(sweep), "run folder")  # a link that loops or leads nowhere, a name too long: said so
        raise UserError(f"{sweep} is not a sweep folder (it has no {METHODS}/): give --run the folder a sweep wrote")
    found = {
        f.name: read_json(f / RESULTS_FILE, ("results",))["results"]
        for f in arm_folders(sweep)
        if (f / RESULTS_FILE).is_file()
    }
    if not found:
        raise UserError(f"{sweep} has no finished method yet (no {METHODS}/*/{RESULTS_FILE})")
    return found


# ---------------------------------------------------------------------- one writer per folder
LOCK_FILE = ".lock"
_held: dict[Path, object] = {}  # folder -> its lock (a file descriptor, or filelock's), for this process's life


# What a file system takes: a name of at most 255 bytes (ext4, APFS, NTFS), a path of at
# most 4096 (Linux's PATH_MAX). A longer one fails with ENAMETOOLONG.
NAME_MAX = 255
PATH_MAX = 4096


def _shown(text: str) -> str:
    """A name too long to print whole, shortened for a one-line message."""
    return text if len(text) <= 60 else f"{text[:40]}...{text[-12:]}"


def check_path(path: Path, what: str = "--out") -> None:
    """A UserError, before anything is written, where the folder `path` (given as `what`)
    cannot be made or used: a name in it longer than a file system takes (`NAME_MAX` bytes;
    ENAMETOOLONG), the whole path longer than `PATH_MAX`, or a symbolic link on the way
    that loops (ELOOP) or leads nowhere."""
    path = Path(path)
    for part in path.parts:
        size = len(os.fsencode(part))
        if size > NAME_MAX:
            raise UserError(
                f"{what} {_shown(str(path))}: the name {_shown(part)} is {size} bytes, longer than the {NAME_MAX} "
                "a file or folder name can have; choose a shorter one"
            )
    size = len(os.fsencode(str(path.absolute())))
    if size >= PATH_MAX:
        raise UserError(
            f"{what} {_shown(str(path))}: the path is {size} bytes, longer than the {PATH_MAX - 1} a path can have; "
            "choose a shorter one"
        )
    step = Path(path.anchor) if path.anchor else Path()
    for part in path.parts[1 if path.anchor else 0 :]:
        step = step / part
        try:
            os.stat(step)
        except OSError as e:
            if e.errno == errno.ELOOP:
                raise UserError(
                    f"{what} {path}: {step} is a symbolic link that leads back to itself (a loop); remove the link, "
                    f"or choose another {what}"
                ) from None
            if os.path.islink(step):
                raise UserError(
                    f"{what} {path}: {step} is a symbolic link to {os.readlink(step)}, which is not there; make that "
                    f"folder, remove the link, or choose another {what}"
                ) from None
            return  # not there (made later), or under a file (`claim` says so)


def claim(path: Path) -> None:
    """Make this process the one writer of the folder `path` (created if missing): an
    exclusive OS lock (flock) on `path`/.lock, held until the process exits (a crash
    releases it; the file left behind locks nothing). Another process holding it is a
    UserError naming its pid; claiming a folder this process holds is a no-op. In a program
    `run_cli` runs, a refusal releases the claim and deletes the .lock and the folders it
    made (`errors.on_refusal`, `_release`): a refused command leaves --out as it found it."""
    path = Path(path)
    check_path(path)
    if path.exists() and not path.is_dir():
        raise UserError(f"{path} is a file, not a folder; choose another --out")
    made = next((p for p in (*reversed(path.absolute().parents), path.absolute()) if not p.exists()), None)
    path.mkdir(parents=True, exist_ok=True)
    key = path.resolve()
    if key in _held:
        return
    if not os.access(path, os.W_OK | os.X_OK):  # read-only: refused before any work, not at its end
        if made is not None:
            _remove_empty(key, made)
        raise UserError(
            f"{path} is read-only (this user cannot write in it, or its file system is mounted read-only); "
            "make it writable, or copy it to a folder you can write and give that"
        )
    new_lock = not (path / LOCK_FILE).exists()
    if fcntl is None:
        _held[key] = _claim_with_filelock(path)
    else:
        fd = os.open(path / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.read(fd, 64).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise UserError(
                f"{path} is being written by another process (pid {holder}); wait for it to finish, "
                "or choose another --out"
            ) from None
        os.ftruncate(fd, 0)
        os.write(fd, str(os.getpid()).encode())
        _held[key] = fd
    on_refusal(lambda: _release(key, new_lock, made))


def _release(key: Path, new_lock: bool, made: Path | None) -> None:
    """Undo a `claim` of a refused program: release the lock, delete the .lock file if the
    claim made it, and the folders it made (`made`: the topmost) if they hold nothing else."""
    held = _held.pop(key, None)
    if held is None:
        return
    held.release() if fcntl is None else os.close(held)
    if new_lock:
        (key / LOCK_FILE).unlink(missing_ok=True)
    if made is not None:
        _remove_empty(key, made)


def _remove_empty(key: Path, made: Path) -> None:
    """Delete the folder `key` and those above it up to `made` (what a claim made), while empty."""
    for folder in (key, *key.parents):
        if not folder.is_dir() or any(folder.iterdir()):
            break
        folder.rmdir()
        if folder == made.resolve():
            break


def _claim_with_filelock(path: Path):
    """`claim` where there is no fcntl (native Windows): filelock's lock on the same .lock
    file (a dependency there only: pyproject.toml), held by the returned object."""
    import filelock  # installed on Windows alone (pyproject.toml's marker)

    lock = filelock.FileLock(str(path / LOCK_FILE))
    try:
        lock.acquire(timeout=0)
    except filelock.Timeout:
        raise UserError(
            f"{path} is being written by another process; wait for it to finish, or choose another --out"
        ) from None
    return lock


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
    check_path(path)  # before `exists`, which a name too long for the file system fails
    if resume:
        if not path.exists():
            raise RunNotFound(f"{path} is not there; nothing to resume (give the --out it was started with)")
        if not (path / marker).is_file():
            raise UserError(f"{path} is not a {kind} folder (no {marker}); nothing to resume")
        claim(path)
        return
    if path.exists() and path.is_dir() and _contents(path):
        if (path / marker).is_file():
            claim(path)  # a folder of ours that another process is writing: say so, with its pid
        if not overwrite:
            hint = (
                "use --resume to continue it or --overwrite to replace it"
                if kind == "run"
                else ("use --overwrite to replace it or choose another --out")
            )
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
    clash, ignored = [], []
    for f in dataclasses.fields(args):
        if f.name in (*keep, "resume", "overwrite", "out"):
            continue
        mine, theirs, default = (getattr(x, f.name) for x in (args, started, defaults))
        flag = f"--{f.name.replace('_', '-')} {mine} (started with {theirs})"
        if dataclasses.is_dataclass(mine):  # nested flags (e.g. Config fields): each on its own
            clash += [
                f"--{k.replace('_', '-')} {v} (started with {getattr(theirs, k)})"
                for k, v in dataclasses.asdict(mine).items()
                if v is not None and jsonable(v) != jsonable(getattr(theirs, k))
            ]
        elif jsonable(mine) not in (jsonable(default), jsonable(theirs)):
            clash.append(flag)
        elif jsonable(mine) != jsonable(theirs) and f.name in given_flags():  # given at its default
            ignored.append(flag)
    if clash:
        raise UserError(
            f"--resume continues {args.out} with the arguments it was started with; drop {', '.join(clash)}"
        )
    say_ignored(ignored, args.out)
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


def code_commit() -> str | None:
    """The commit of the checkout this code runs from (`git rev-parse HEAD` beside the
    `experiments` package), with "+dirty" where tracked files differ from it; None outside a
    git checkout (an installed wheel). Runs record it (run.json's "commits"), so a study's
    plan can be checked to precede them (docs/plans/)."""
    root = Path(__file__).resolve().parents[1]
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=30)
        if head.returncode != 0:
            return None
        dirty = subprocess.run(["git", "-C", str(root), "diff", "--quiet", "HEAD", "--", "."], timeout=30).returncode
    except (OSError, subprocess.SubprocessError):
        return None
    return head.stdout.strip() + ("+dirty" if dirty else "")


def with_commit(info: dict, previous: dict | None) -> dict:
    """run.json's `info` with "commits": the commits that trained the run, in order (those
    `previous`, the run.json on disk, lists, then this checkout's where it differs from the
    last)."""
    commits = list((previous or {}).get("commits", []))
    commit = code_commit()
    if commit is not None and (not commits or commits[-1] != commit):
        commits.append(commit)
    return {**info, "commits": commits}


def write_run_info(path: Path, info: dict) -> None:
    write_json(path / RUN_FILE, info)


def require_run(path: Path, hint: str = "; pass the --out folder of experiments.train") -> None:
    """A RunNotFound, saying whether `path` is not there or holds no run.json, unless it is a run."""
    if not is_run(Path(path)):
        check_path(Path(path), "run folder")  # a link that loops or leads nowhere, a name too long: said so
        what = "is not there" if not Path(path).exists() else f"is not a run folder (no {RUN_FILE})"
        raise RunNotFound(f"{path} {what}{hint}")


def read_run_info(path: Path) -> dict:
    require_run(path)
    return read_json(path / RUN_FILE, RUN_KEYS)


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


# ---------------------------------------------------------------------- CSV
def write_csv(path: Path, rows: list[dict], append: bool = False) -> None:
    """Rows of dicts as CSV, columns in the first row's key order; a header only when the
    file is new. NaN and missing values (None, e.g. read back from strict JSON's null) are
    written `nan`, as Python's csv writes a float NaN, so a row reads the same either way.
    No rows: an empty file (a table of nothing that ran), or nothing appended."""
    path = Path(path)
    if not rows:
        if not append:
            path.write_text("")
        return
    new = not (append and path.exists())
    with open(path, "a" if append else "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        if new:
            writer.writeheader()
        writer.writerows({k: _csv_cell(v) for k, v in row.items()} for row in rows)


def _csv_cell(value):
    return "nan" if value is None or (isinstance(value, float) and math.isnan(value)) else value


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


def truncate_rows(path: Path, last_update: int, rows: list[dict] | None = None) -> None:
    """Drop rows after `last_update` (written after the checkpoint a resume starts from)
    and a cut last line (`read_rows`, or `rows` it returned); each file is replaced whole
    (written, then renamed: a kill leaves the old file or the new one)."""
    rows = [r for r in (read_rows(path) if rows is None else rows) if r["update"] <= last_update]
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
