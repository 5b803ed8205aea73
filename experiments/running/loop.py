"""The run loop's parts (`experiments.running.run.Run.train` is the loop, a plain `for` over
chunks: learn, check, validate and select, record, checkpoint):

    resume_point       where a resumed run continues: its newest intact checkpoint
    chunk_sizes        the chunks from where the run stands to its end, while the
                       invocation's chunk budget (--stop-after-chunks) lasts and no stop
                       was asked for (Ctrl-C: `interruptible`, `StopRequest`)
    check              a chunk's metrics and state before anything of it is recorded: stop,
                       naming the update and the seed, on a non-finite loss or parameter;
                       warn of divergence short of NaN
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from pathlib import Path
from typing import Iterator, NamedTuple, Optional, Sequence

import jax
import numpy as np

from experiments import errors
from experiments.running import checkpoint


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
            found.append(
                f"{name.split('/')[-1]} reached {np.nanmax(np.where(np.isnan(x), -np.inf, x)):.3g} (bound {bound:g})"
            )
    entropy = np.asarray(metrics.get("losses/entropy", 1.0), float)
    if (entropy < COLLAPSED_ENTROPY).any():
        found.append(f"the policy's entropy fell to {np.nanmin(entropy):.3g} (collapsed below {COLLAPSED_ENTROPY:g})")
    return "training may be diverging: " + "; ".join(found) + " (a lower --learning-rate may help)" if found else None


def warn(line: str) -> None:
    print(f"warning: {line}", file=sys.stderr, flush=True)


class Chunk(NamedTuple):
    """One chunk of updates, as the run loop hands it to its recorders (`run.Recorder`)."""

    metrics: dict  # name -> [n] (or [seeds, n]) numpy, one value per update
    done: int  # updates done, this chunk included
    n: int  # updates in this chunk
    warning: Optional[str]  # the divergence warning (`divergence`), or None
    started: float  # time.time() when the chunk began (for frames/s)


def resume_point(manager, folder: Path, recorded: Optional[int] = None, label: str = "") -> int:
    """The update a resumed run continues from: its newest intact checkpoint, at most
    `recorded` (the last update the run's own records cover, when it keeps any beyond
    its checkpoints: a sweep's progress.json). Every corrupt checkpoint is skipped,
    saying so, and every one after the step chosen is deleted (those updates run again,
    to the same numbers). 0 when there is none."""
    if recorded is not None:  # saved after the records were: nothing else knows them
        checkpoint.drop_steps_after(manager, recorded)
    if manager.latest_step() is None:
        if recorded:
            warn(f"{label}no checkpoint in {folder}; starting again from update 0")
        return 0
    intact, skipped = checkpoint.intact_step(manager)
    for line in skipped:
        warn(f"{label}{line}; skipped")
    step = intact or 0
    if intact is None:
        warn(f"{label}no intact checkpoint in {folder}; starting again from update 0")
    elif skipped or (recorded is not None and step != recorded):
        warn(f"{label}continuing from update {step}")
    checkpoint.drop_steps_after(manager, step)
    return step


def nonfinite(metrics: dict, state, done: int, n: int, seeds: Optional[Sequence[int]] = None) -> Optional[str]:
    """What went non-finite in a chunk of `n` updates after the first `done`, or None: the
    first update whose loss is NaN or inf, or else the parameters (the loss is computed
    before each update, so a finite loss can leave NaN weights behind). With `seeds`,
    the metrics and the state are stacked over them and the message names the seed."""
    loss = np.asarray(metrics["losses/total_loss"]).reshape(len(seeds) if seeds else 1, -1)
    bad = np.argwhere(~np.isfinite(loss))
    if len(bad):
        seed, update = bad[0]
        return f"non-finite loss at update {done + update + 1}" + (f" of seed {seeds[seed]}" if seeds else "")
    finite = np.atleast_1d(finite_seeds(state, len(seeds) if seeds else None))
    if finite.all():
        return None
    which = f" in seed(s) {[s for s, ok in zip(seeds, finite) if not ok]}" if seeds else ""
    return f"non-finite parameters after update {done + n}{which} (the loss, computed before each update, was finite)"


def kept_checkpoint(manager, folder: Path) -> str:
    """Where a stopped run's last good state is, for its error message."""
    step = manager.latest_step()
    if step is None:
        return "no checkpoint was written (the first chunk diverged)"
    return f"its last checkpoint (update {step}, finite) is kept in {folder}"


class StopRequest:
    """Ctrl-C during a run, as a flag: called as the SIGINT handler (`interruptible`), the
    first call sets `requested` (the run loop stops after the chunk it is in, checkpointed:
    `chunk_sizes`), a second raises KeyboardInterrupt (abort at once; the programs print
    it as one line, `errors.run_cli`)."""

    def __init__(self):
        self.requested = False

    def __call__(self, signum=None, frame=None) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        print(
            "\nCtrl-C: stopping after the current chunk, which is checkpointed (press Ctrl-C again to abort now)",
            file=sys.stderr,
            flush=True,
        )


_STOP: Optional[StopRequest] = None  # the stop request of the run in progress (`interruptible`)


@contextlib.contextmanager
def interruptible() -> Iterator[StopRequest]:
    """For the duration of a run: a `StopRequest`, installed as the SIGINT handler (in the
    main thread; elsewhere only the flag) and as the one `chunk_sizes` checks; the handler
    and the request before are restored after."""
    global _STOP
    request, outer = StopRequest(), _STOP
    main = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGINT, request) if main else None
    _STOP = request
    try:
        yield request
    finally:
        _STOP = outer
        if main:
            signal.signal(signal.SIGINT, signal.SIG_DFL if previous is None else previous)


def stop_requested() -> bool:
    """Whether a stop was asked for in the run in progress (a first Ctrl-C)."""
    return _STOP is not None and _STOP.requested


def chunk_sizes(done: int, total: int, chunk_updates: int, budget: Optional[list] = None) -> Iterator[int]:
    """The sizes of the chunks that train from update `done` to `total`, `chunk_updates`
    each (the last one what remains), while `budget` lasts: a one-item list of the chunks
    this invocation may still run ([None]: no limit; a sweep's arms share it), one spent
    each time the loop's body over a chunk has returned; and until a stop is asked for
    (`stop_requested`: a first Ctrl-C), checked before each chunk, so after the last one's
    checkpoint."""
    while done < total:
        if budget is not None and budget[0] is not None and budget[0] <= 0:
            return
        if stop_requested():
            return
        n = min(chunk_updates, total - done)
        yield n
        done += n
        if budget is not None and budget[0] is not None:
            budget[0] -= 1


def check(
    metrics: dict,
    state,
    done: int,
    n: int,
    *,
    manager,
    checkpoints: Path,
    seeds: Optional[Sequence[int]] = None,
    label: str = "",
) -> Optional[str]:
    """A chunk of `n` updates after the first `done`, checked before anything of it is
    recorded: its metrics (numpy, {name: [n]} or [seeds, n]) and the state it left. A
    non-finite loss or parameter stops the process (exit status 1), naming the update, the
    seed and the last checkpoint (`manager`, in the folder `checkpoints`), which is finite:
    every saved state passed this check. Divergence short of NaN (`divergence`) is warned
    of, and returned (None when there is none)."""
    what = nonfinite(metrics, state, done, n, seeds)
    if what is not None:
        errors.fail(
            f"{label}{what}; training stopped, {kept_checkpoint(manager, checkpoints)}; "
            "a lower --learning-rate may help",
            status=1,
        )
    warning = divergence(metrics)
    if warning:
        warn(f"{label}updates {done + 1}-{done + n}: {warning}")
    return warning
