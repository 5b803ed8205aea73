"""The progress bar of training and sweeps (tqdm).

It moves at the end of each chunk (with the chunk's postfix: frames/s, SR, validation SR)
and, through `advance.at`, inside a chunk: the jitted chunk calls it every 10th update
(`Trainer.run`'s `on_update`), so a 500-update chunk no longer sits still for half a minute.
Without the bar (`--no-progress`, or whenever stderr is not a terminal: a run redirected to
a log file gets no tqdm `\r` frames), each chunk's end is one line on stderr instead: the
clock, updates done of the total, the minutes since the start and the postfix. SR is in
percent there as everywhere (results, tables, `evaluate_policy`).
"""

from __future__ import annotations

import sys
import time

import numpy as np


def is_terminal(stream) -> bool:
    """Whether `stream` is a terminal (a closed or replaced stream without `isatty`: no)."""
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def progress_bar(total: int, initial: int, enabled: bool, tty: bool | None = None):
    """A tqdm bar over `total` updates starting at `initial` when `enabled` and stderr is a
    terminal (`tty`; None: asks `sys.stderr.isatty()`), else one plain line per chunk (what
    `--no-progress` gives); returns `advance(n, postfix)`:
    call it with (n, {name: value}) after each chunk of n updates and with (0, None) to
    close the bar. `advance.at(position)` moves the bar to `position` updates within a
    chunk (never back; a vmapped chunk passes every seed's count, the furthest is taken);
    `advance.skip(position)` moves it to where a resumed run starts, logging nothing."""
    from tqdm import tqdm

    enabled = bool(enabled) and (is_terminal(sys.stderr) if tty is None else bool(tty))
    bar = tqdm(
        total=total,
        initial=initial,
        unit="upd",
        disable=not enabled,
        dynamic_ncols=True,
        bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} updates [{elapsed}<{remaining}{postfix}]",
    )
    chunk_end = [initial]
    started = time.time()

    def advance(n: int, postfix: dict | None) -> None:
        if postfix is None:
            bar.close()
            return
        chunk_end[0] += n
        bar.set_postfix(postfix, refresh=False)
        bar.update(chunk_end[0] - bar.n)
        if not enabled and n:
            print(log_line(chunk_end[0], total, time.time() - started, postfix), file=sys.stderr, flush=True)

    def at(position) -> None:
        position = int(np.max(position))
        if position > bar.n:
            bar.update(position - bar.n)

    def skip(position: int) -> None:
        """Move to `position` updates (where a resumed run starts) without logging a line,
        and without counting them in the rate (and so the ETA): as tqdm's `initial` would."""
        delta = int(position) - chunk_end[0]
        if delta > 0:
            chunk_end[0] += delta
            bar.n += delta
            if not bar.disable:
                bar.initial += delta
                bar.last_print_n = bar.n
                bar.refresh()

    advance.at = at
    advance.skip = skip
    advance.position = lambda: chunk_end[0]  # where the last chunk ended
    advance.enabled = enabled
    return advance


def log_line(done: int, total: int, seconds: float, postfix: dict) -> str:
    """A chunk's end as one line of a log: '[HH:MM:SS] 2000/36000 updates, 26.0 min: method
    a3c, SR 12.3%'."""
    fields = ", ".join(f"{name} {value}" for name, value in postfix.items())
    line = f"[{time.strftime('%H:%M:%S')}] {done}/{total} updates, {seconds / 60:.1f} min"
    return line + (f": {fields}" if fields else "")
