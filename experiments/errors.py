"""What the user asked wrongly, as one line: `UserError`, and `run_cli`, the body of every
program (tyro parses the flags; a UserError, a ValueError or an OSError of the user's
disk or paths is one line on stderr and an exit status, never a traceback); `read_json`,
a file of a run folder read back, a damaged one a UserError naming it.

A leaf: it imports nothing of the project, so that both layers of the programs' machinery
(experiments/reporting below, experiments/running above it) can raise the same error."""

from __future__ import annotations

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
    asked wrongly (UserError, ValueError, a number too large) is one line on stderr and
    exit status 2, XLA's out-of-memory one line and exit status 1."""
    import tyro

    args = tyro.cli(args_class, args=argv)
    try:
        return main(args)
    except (UserError, ValueError) as e:
        fail(str(e))
    except OverflowError as e:  # a number past what jax or numpy holds (a seed of 2**70)
        fail(f"a number given is too large ({e}); give a smaller --seed, size or count")
    except RuntimeError as e:  # XLA's out-of-memory, raised as jaxlib's XlaRuntimeError
        if "RESOURCE_EXHAUSTED" not in str(e):
            raise
        fail(f"out of memory ({str(e).splitlines()[0][:160]}); lower --num-lanes or --seeds, or train on a larger "
             "device", status=1)  # fmt: skip
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


def read_json(path: Path):
    """A JSON file this project wrote; a broken one is a UserError naming it."""
    try:
        return json.loads(Path(path).read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise UserError(f"{path} is not valid JSON ({e}); it was damaged after it was written") from None
