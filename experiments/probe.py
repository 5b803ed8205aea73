"""Probe a trained agent's imagination: `python -m experiments.probe --run runs/quick`.

`--run` is a run folder of `experiments.train` or a sweep folder of `experiments.sweep`
(every finished method with imagination or the attention critic, or `--methods`; every
seed). For each seed's selected model (`experiments.analysis.probes` has the functions):

* test SR on the same test episodes (the run's test key, `--episodes-per-room` per room
  type) with i_tau as the default evaluation gives it (the trained f_w, the noise at the
  end of training, whatever `Config.evaluation_noise` the run used), with the noise off, from an untrained f_w (the run's initial w),
  shuffled across episodes, and shuffled with the noise off (only i_tau's content moves); for a method evaluated greedily (ORG), also with sampled
  actions. Each condition is paired with the first over the seeds (`experiments.reporting.stats`);
* f_w against its targets on `--windows` fresh training windows of the agent (held out:
  f_w never trained on them): smooth-L1, R^2 over the targets' mean, and over each target
  category's mean; what f_w's inputs tell, fit on half the items: s_0 itself, ridge on
  [s_0 : g], f_w's architecture trained offline (`experiments.analysis.probes.imagination_fit`);
  the variance of f_w's outputs beside the noise's;
* where the sub-goal falls in its successful episode: t*/T and the share at the Done step.

Writes `probe.md` and `probe.json` into `--run` or `--out` (refusing to replace them without
`--overwrite`) and prints the Markdown.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path
from typing import Optional

from experiments import errors
from experiments.reporting import probing
from experiments.running import probe_runs
from experiments import rundir
from experiments.running.models import models_of_run, models_of_sweep


@dataclasses.dataclass(frozen=True)
class Args:
    """Probe whether a trained agent uses its imagination, and what f_w learned."""

    run: Path
    """A run folder (experiments.train) or a sweep folder (experiments.sweep)."""
    methods: tuple[str, ...] = ()
    """For a sweep: the methods to probe (default: every finished one with imagination or
    the attention critic)."""
    episodes_per_room: int = 100
    """Test episodes per room type for each condition."""
    windows: int = 40
    """Training windows played to collect f_w's held-out items and the sub-goals."""
    fit_options: bool = False
    """Also replay f_w's online training with other options (`experiments.reporting.probing.FIT_OPTIONS`) on the same
    items at the trained encoder, from the run's initial f_w, streamed --fit-passes times:
    which procedure fits as well as the offline f_w."""
    fit_passes: int = 5
    """How many times the items are streamed through each replayed option."""
    out: Optional[Path] = None
    """Folder for probe.md and probe.json (default: --run)."""
    overwrite: bool = False
    """Replace an existing probe.md / probe.json."""


def main(args: Args) -> dict:
    if args.episodes_per_room < 1 or args.windows < 1 or args.fit_passes < 1:
        raise errors.UserError("--episodes-per-room, --windows and --fit-passes must be >= 1")
    folder = args.run if args.out is None else args.out
    out_md, out_json = folder / "probe.md", folder / "probe.json"
    if out_json.exists() and not args.overwrite:
        raise errors.UserError(f"{out_json} exists; pass --overwrite to replace it")
    t0 = time.time()
    if rundir.is_sweep(args.run):
        models = models_of_sweep(args.run, args.methods)
    else:
        if args.methods:
            raise errors.UserError("--methods is for a sweep folder; a run folder holds one method")
        models = models_of_run(args.run)
    if not models:
        raise errors.UserError(f"{args.run}: no finished method with imagination or the attention critic to probe")
    rundir.claim(folder)  # the one writer of the folder, and writable, before the probe's work
    report = probe_runs.probe(models, args.episodes_per_room, args.windows, args.fit_passes if args.fit_options else 0)
    md = probing.markdown(report, args.episodes_per_room, args.windows)
    folder.mkdir(parents=True, exist_ok=True)
    rundir.write_json(
        out_json,
        {
            "episodes_per_room": args.episodes_per_room,
            "windows": args.windows,
            "fit_passes": args.fit_passes if args.fit_options else 0,
            "methods": report,
        },
    )
    out_md.write_text(md)
    print(md)
    print(f"wrote {out_md} and {out_json} ({time.time() - t0:.0f} s)")
    return report


def cli(argv=None) -> None:
    errors.run_cli(Args, main, argv)


if __name__ == "__main__":
    cli(sys.argv[1:])
