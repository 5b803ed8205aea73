"""The run flags: the flags that the programs which train (train, sweep, tune, paper) share,
each declared here once, with its one help text.

Each is an annotated type, the field's type with its help (tyro prints it), which a
program's `Args` (or `sweeps.Sweep`) gives its field of that name, with the default:

    num_updates: flags.NumUpdates = None
    resume: flags.Resume = False

rather than fields of a shared base or nested dataclass: the fields keep their names and
places, and so every flag its name, and the arguments saved in a folder (sweep.json,
tune.json, paper.json: `rundir.write_started_args`) their layout.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import tyro

from experiments.errors import UserError

# What a run trains: the preset's values, unless given.
NumUpdates = Annotated[
    Optional[int],
    tyro.conf.arg(
        help=(
            "Override the preset's number of updates. With --resume, train and sweep extend a run to a larger number "
            "(as if it had asked for it from the start; its earlier results are kept beside)."
        )
    ),
]
TestEpisodes = Annotated[Optional[int], tyro.conf.arg(help="Override the preset's test episodes per room type.")]
ValEpisodes = Annotated[
    Optional[int],
    tyro.conf.arg(
        help=("Override the preset's validation episodes per room type (model selection, after each chunk).")
    ),
]
Reuse = Annotated[
    tuple[Path, ...],
    tyro.conf.arg(
        help=(
            "Folders whose finished arms are taken into --out instead of trained: sweeps (experiments.sweep), and tunes "
            "for tune, paper runs for paper, of the same protocol (setup, preset and overrides). They combine seed by "
            "seed: an arm whose every seed they finished between them is copied or assembled (each seed from the first "
            "folder that has it), e.g. rows run on another machine, or seeds 2-4 (--seed 2 --seeds 3) added to a run of "
            "seeds 0-1; an arm they finish only some seeds of is trained here."
        )
    ),
]

# What this invocation does with --out.
Resume = Annotated[
    bool,
    tyro.conf.arg(
        help=(
            "Continue what was started in --out where it stopped (what finished is kept; what was training continues "
            "from its last intact checkpoint), with the arguments it was started with: another value given is refused "
            "(one given at its default is ignored, and a line names it), except a larger --num-updates in train and "
            "sweep, which extends it."
        )
    ),
]
Overwrite = Annotated[
    bool,
    tyro.conf.arg(
        help=("Replace what this program wrote in --out and start again (a folder it did not write is never deleted).")
    ),
]
StopAfterChunks = Annotated[
    Optional[int],
    tyro.conf.arg(
        help=(
            "Stop (as if killed) after this many chunks trained by this invocation (paper: by each of its sweeps); "
            "for testing --resume. At least 1 (sweep, tune, paper: 0 trains nothing, e.g. only takes what --reuse "
            "finished). Ctrl-C does the same after the current chunk (a second Ctrl-C aborts at once)."
        )
    ),
]
Progress = Annotated[
    bool,
    tyro.conf.arg(
        help="Show the progress bar on a terminal; off one (stderr redirected), and with --no-progress, one plain "
        "line per chunk instead."
    ),
]
AllowLarge = Annotated[
    bool,
    tyro.conf.arg(
        help=(
            "Run past the size bounds instead of refusing: --num-updates over 10**7, --seeds over 4096, or a training "
            "window whose observations alone exceed the machine's memory (experiments.running.presets.check_sizes)."
        )
    ),
]

# This invocation's own flags: a program that saves its arguments for --resume saves
# neither these nor resume and overwrite (`rundir.write_started_args`), and takes them
# from the resuming invocation (`rundir.resumed_args`).
INVOCATION = ("stop_after_chunks", "progress", "allow_large")


def check_stop_after_chunks(value: Optional[int], least: int = 1) -> None:
    """A one-line UserError, before anything is written, for a --stop-after-chunks below
    `least` (train: 1, a run that trains nothing would only write an empty folder; sweep,
    tune and paper: 0, which takes what --reuse finished and trains nothing)."""
    if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < least):
        what = "train at least one chunk" if least == 1 else "0 trains nothing"
        raise UserError(
            f"--stop-after-chunks must be >= {least} ({what}), got {value!r}; leave it out to train to the end"
        )
