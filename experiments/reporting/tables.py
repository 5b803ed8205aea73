"""Tables written by the experiments: Markdown (reports, the paper's layout) and CSV.

`markdown_table(rows, columns)` is the one Markdown table writer (run reports, sweep tables,
the demo, the benchmarks); CSV files are written by `experiments.rundir.write_csv`.
"""

from __future__ import annotations

import math
from typing import Optional, Sequence

from foresit_jax.methods import parse_method


def markdown_table(rows: Sequence[Sequence], columns: Sequence[str], align: Optional[str] = None) -> str:
    """A Markdown table: the header `columns`, a rule, and one line per row of cells
    (each cell written with `str`). No trailing newline.

    `align`: None writes cells as they are (`| a | b |`); one character per column, '<'
    (left) or '>' (right), pads every column to its widest cell, for a table that also reads
    well as plain text (the benchmarks print it)."""
    columns = [str(c) for c in columns]
    rows = [[str(cell) for cell in row] for row in rows]
    for row in rows:
        if len(row) != len(columns):
            raise ValueError(f"a row has {len(row)} cells for {len(columns)} columns: {row}")
    if align is None:
        lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
        return "\n".join(lines + ["| " + " | ".join(row) + " |" for row in rows])
    if len(align) != len(columns) or set(align) - {"<", ">"}:
        raise ValueError(f"align needs one '<' or '>' per column ({len(columns)}), got {align!r}")
    widths = [max(len(cell) for cell in column) for column in zip(columns, *rows)]

    def line(cells):
        return "| " + " | ".join(f"{c:{a}{w}}" for c, a, w in zip(cells, align, widths)) + " |"

    return "\n".join([line(columns), "|" + "|".join("-" * (w + 2) for w in widths) + "|"] + [line(r) for r in rows])


RESULT_COLUMNS = ("SPL", "SR", "SPL>=5", "SR>=5")  # Table 1's columns
HOUSE_COLUMNS = ("SPL>=10", "SR>=10", "SPL>=20", "SR>=20")  # and the houses' longer buckets (envs.metrics)


PRIVILEGED_NOTE = (
    "privileged: i_tau is what no agent can see (the oracle: the agent's latent of its episode's "
    "goal view; optaction, compass, startcompass: the oracle's action, the target's bearing and "
    "distance); a diagnostic of what a channel can carry (docs/ceiling.md), never a method"
)


def arm_label(arm: str) -> str:
    """An arm's name as reports print it: `a3c+oracle (privileged)` for a method that reads
    what no agent can see (`Method.privileged`), else the name itself."""
    try:
        privileged = parse_method(arm.split("@")[0]).privileged
    except ValueError:  # not a method name (a pair's label, a condition)
        privileged = False
    return f"{arm} (privileged)" if privileged else arm


def results_markdown(results: dict, title: str, level: int = 1) -> str:
    """One row per room type (and overall); houses' results add their L >= 10, 20 columns."""
    first = next(iter(results.values()))
    cols = RESULT_COLUMNS + tuple(c for c in HOUSE_COLUMNS if c in first)
    rows = [[room, *(_fmt(m[c]) for c in cols), m["episodes"]] for room, m in results.items()]
    return "#" * level + f" {title}\n\n" + markdown_table(rows, ["rooms", *cols, "episodes"]) + "\n"


def _fmt(x: float) -> str:
    return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.2f}"
