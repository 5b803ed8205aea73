"""Did each auxiliary target's head learn? `python -m experiments.target_probe --run runs/targets_stage1`.

`--run` is a sweep folder (every arm with `aux_target`, or `--methods`) or one run folder. For
every seed, the final training state plays `--episodes` whole test episodes with the target's
labels beside it, and its head is scored against a predictor of the mean label
(`experiments.running.target_probe`: the compass's angular error and the R² of its distance;
a latent's R² and the spread of its labels across episodes beside the states'). Writes
`targets_probe.json` into `--run` (or `--out`, a file), refusing to replace one without
`--overwrite`, and prints a table. Run it before a sweep's checkpoints are dropped: it reads
them.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Optional

import numpy as np

from experiments import errors, rundir
from experiments.reporting.tables import markdown_table
from experiments.running import models, target_probe

OUT_FILE = "targets_probe.json"


@dataclasses.dataclass(frozen=True)
class Args:
    """Score each auxiliary target's head against the mean label on test episodes."""

    run: Path
    """A sweep folder (experiments.sweep) or a run folder (experiments.train)."""
    methods: tuple[str, ...] = ()
    """For a sweep: the arms to probe (default: every arm with an auxiliary target)."""
    episodes: int = 400
    """Test episodes per seed (the same episodes for every seed and arm)."""
    seed: int = 0
    """The test episodes' key."""
    out: Optional[Path] = None
    """The JSON file to write (default: <run>/targets_probe.json)."""
    overwrite: bool = False
    """Replace an existing output file."""


def folders(args: Args) -> dict[str, Path]:
    """{arm: run folder} to probe."""
    if not rundir.is_sweep(args.run):
        rundir.require_run(args.run, "; pass a sweep folder or a run folder of experiments.train")
        return {rundir.read_run_info(args.run)["arm"]: args.run}
    found = {f.name: f for f in rundir.arm_folders(args.run)}
    if args.methods:
        missing = [m for m in args.methods if m not in found]
        if missing:
            raise errors.UserError(f"--methods: {args.run} has no arm(s) {missing}; it has {sorted(found)}")
        return {m: found[m] for m in args.methods}
    chosen = {arm: f for arm, f in found.items() if "aux_target=" in arm}
    if not chosen:
        raise errors.UserError(f"{args.run} has no arm with an auxiliary target (aux_target=...)")
    return chosen


def table(report: dict[str, list[dict]]) -> str:
    """One row per arm: each measure's mean over seeds, and how many seeds' heads learned."""
    rows = []
    for arm, seeds in report.items():
        names = [k for k in seeds[0] if k not in ("seed", "learned")]
        cells = ", ".join(f"{k} {np.nanmean([s[k] for s in seeds]):.3g}" for k in names)
        rows.append([arm, f"{sum(s['learned'] for s in seeds)}/{len(seeds)}", cells])
    return markdown_table(rows, ["arm", "heads learned", "means over seeds"])


def main(args: Args) -> dict:
    if args.episodes < 1:
        raise errors.UserError(f"--episodes must be >= 1, got {args.episodes}")
    out = args.out or args.run / OUT_FILE
    if out.exists() and not args.overwrite:
        raise errors.UserError(f"{out} exists; pass --overwrite to replace it")
    chosen = folders(args)
    report = {
        arm: target_probe.probe_run(models.read_trained(f), args.episodes, args.seed) for arm, f in chosen.items()
    }
    rundir.write_json(out, {"episodes": args.episodes, "seed": args.seed, "arms": report})
    print(table(report))
    print(f"wrote {out}")
    return report


def cli(argv=None) -> None:
    errors.run_cli(Args, main, argv)


if __name__ == "__main__":
    cli()
