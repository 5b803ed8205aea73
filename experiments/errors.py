"""What the user asked wrongly, as one line: `UserError`, and `run_cli`, the body of every
program (tyro parses the flags; a UserError, a ValueError or an OSError of the user's
disk or paths is one line on stderr and an exit status, never a traceback); `read_json`,
a file of a run folder read back, a damaged one a UserError naming it.

A leaf: it imports nothing of the project, so that both layers of the programs' machinery
(experiments/reporting below, experiments/running above it) can raise the same error."""

from __future__ import annotations

import contextvars
import errno
import json
import sys
from pathlib import Path


class UserError(ValueError):
    """A problem with what the user asked for: printed as one line, exit status 2. A
    ValueError, so that library code catching bad values catches it too."""


class RunNotFound(UserError, FileNotFoundError):
    """A run folder that is not there, or holds no run.json: `except FileNotFoundError`
    and `except UserError` both catch it."""


def fail(message: str, status: int = 2) -> None:
    print(f"error: {message}", file=sys.stderr)
    raise SystemExit(status)


def run_cli(args_class, main, argv=None):
    """A CLI's body: parse `argv` into `args_class` with tyro and run `main`; what the user
    asked wrongly (UserError, ValueError, a number too large, a path the OS refuses) is one
    line on stderr and exit status 2, XLA's out-of-memory one line and exit status 1, a
    Ctrl-C that ends the program (`experiments.running.loop.interruptible`) one line and
    exit status 130."""
    import tyro

    argv = sys.argv[1:] if argv is None else list(argv)
    args = tyro.cli(args_class, args=argv, prog=program_name(args_class))
    given = _GIVEN.set(frozenset(t[2:].split("=")[0].replace("-", "_") for t in argv if t.startswith("--")))
    undo = _UNDO.set([])
    try:
        return main(args)
    except (UserError, ValueError) as e:
        refuse(str(e))
    except OverflowError as e:  # a number past what jax or numpy holds (a seed of 2**70)
        refuse(f"a number given is too large ({e}); give a smaller --seed, size or count")
    except RuntimeError as e:  # XLA's out-of-memory, raised as jaxlib's XlaRuntimeError
        if "RESOURCE_EXHAUSTED" not in str(e):
            raise
        refuse(
            f"out of memory ({str(e).splitlines()[0][:160]}); lower --num-lanes or --seeds, or train on a larger "
            "device",
            status=1,
        )
    except OSError as e:  # disk full, read-only, not a directory: one line, not a traceback
        if e.errno not in _USER_ERRNOS:
            raise
        refuse(os_message(e), status=1 if e.errno in (errno.ENOSPC, errno.EDQUOT) else 2)
    except KeyboardInterrupt:  # a second Ctrl-C in a run (the first stops it after its chunk), or one outside
        fail(
            "interrupted (Ctrl-C); what was written is kept: a run continues from its last checkpoint with --resume",
            status=130,
        )
    finally:
        _GIVEN.reset(given)
        _UNDO.reset(undo)


def refuse(message: str, status: int = 2) -> None:
    """`fail`, after undoing what the refused program made only to hold its folders
    (`on_refusal`): its lock files and the empty folders made to hold them."""
    for undo in reversed(_UNDO.get() or []):
        undo()
    fail(message, status)


# What to undo if the program `run_cli` is running is refused (`on_refusal`).
_UNDO: contextvars.ContextVar[list | None] = contextvars.ContextVar("undo_on_refusal", default=None)


def on_refusal(undo) -> None:
    """Call `undo()` if the program `run_cli` is running ends in a refusal (a UserError and
    the like, before `fail`); outside `run_cli` (a program's `main` called directly),
    nothing. rundir's `claim` registers the release of its lock here, so that a refused
    program leaves no .lock (and no empty folder) behind."""
    pending = _UNDO.get()
    if pending is not None:
        pending.append(undo)


# The flags on the command line `run_cli` is running (field names: `--num-lanes 8` gives
# "num_lanes"), for what the parsed arguments cannot tell: a flag given at its default.
_GIVEN: contextvars.ContextVar[frozenset[str]] = contextvars.ContextVar("given_flags", default=frozenset())


def given_flags() -> frozenset[str]:
    """The flags written on the command line of the program `run_cli` runs (as field
    names); empty where a program's `main` is called directly."""
    return _GIVEN.get()


def say_ignored(ignored: list[str], out) -> None:
    """One line on stderr naming the flags --resume ignored (`ignored`: `--flag value (the
    run has ...)`), if any."""
    if ignored:
        print(
            f"note: --resume continues {out} with the arguments it was started with; ignored {', '.join(ignored)}",
            file=sys.stderr,
            flush=True,
        )


# What the user's disk or paths did, not a bug: reported in one line.
_USER_ERRNOS = {
    errno.ENOSPC,
    errno.EDQUOT,
    errno.EROFS,
    errno.EACCES,
    errno.EPERM,
    errno.ENOTDIR,
    errno.EISDIR,
    errno.EEXIST,
    errno.ENOENT,
    errno.ENAMETOOLONG,
    errno.ELOOP,
}


_OS_HINTS = {
    errno.ENOSPC: " (free some space, then continue with --resume)",
    errno.EDQUOT: " (free some space, then continue with --resume)",
    errno.ENAMETOOLONG: " (choose a shorter path)",
    errno.ELOOP: " (a symbolic link on the path leads back to itself: remove it, or choose another path)",
}


def os_message(e: OSError) -> str:
    where = f"{e.filename}: " if e.filename else ""
    if len(where) > 160:  # a path too long for the file system, as one readable line
        where = f"{where[:80]}...{where[-40:]}"
    return f"{where}{e.strerror or e}" + _OS_HINTS.get(e.errno, "")


def read_json(path: Path, keys: tuple[str, ...] = ()):
    """A JSON object this project wrote, holding `keys`; a broken one (not JSON, not an
    object, a key missing) is a UserError naming it."""
    try:
        value = json.loads(Path(path).read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise UserError(f"{path} is not valid JSON ({e}); it was damaged after it was written") from None
    if not isinstance(value, dict):
        raise UserError(
            f"{path} holds a JSON {type(value).__name__}, not the object this project wrote; it was "
            "damaged after it was written"
        )
    missing = [k for k in keys if k not in value]
    if missing:
        raise UserError(f"{path} lacks {', '.join(missing)}; it was damaged after it was written")
    return value


def program_name(args_class) -> str | None:
    """`python -m experiments.<name>`, the usage line of a program's `--help` (tyro's `prog`;
    without it the usage line is the module's file path), for a program whose `Args` is
    defined in `experiments.<name>` (run as `python -m`, its module is `__main__`: its spec
    names it); None otherwise (tyro's own)."""
    module = getattr(args_class, "__module__", "")
    if module == "__main__":
        spec = getattr(sys.modules.get("__main__"), "__spec__", None)
        module = getattr(spec, "name", "") or ""
    return f"python -m {module}" if module.startswith("experiments.") else None
