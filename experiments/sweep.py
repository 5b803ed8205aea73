"""Seed sweep: `python -m experiments.sweep --methods a3c a3c+foresit --seeds 5 --preset quick`.

Each method's seeds run vmapped inside one jitted program (in chunks, for progress),
spread over the local devices along the seed axis (experiments.running.devices).  The protocol is
`train`'s (experiments.running.selection): seed i of the sweep is seed `--seed + i`, initialised
from the key `train --seed <seed + i>` uses; after each chunk each seed is validated on
the episodes that run would validate on, and the model with the best validation SR is the
one tested, on that run's test episodes.  So a seed's numbers are those of its `train` run
with the same preset and schedule, up to the float rounding of a vmapped program (the
batched matmuls differ in the last bits); over many updates that rounding grows into
another trajectory (at quick: the same training curve for the first ~100 updates, then
apart), so long runs agree in distribution, not in value.  The last model is tested too,
for comparison.

Written: the paper's Table 1 layout (SPL, SR, SPL>=5, SR>=5: mean, sample std and 95%
confidence interval over seeds) of the selected models as Markdown and CSV; every method
against the first one, paired seed by seed (difference, interval, p, verdict); the
selected and last models' SR per seed; every seed's results, validation history and
training curve (JSON); one learning-curve PNG of every method (mean and band over seeds).
`--resume` continues a killed sweep, and with `--num-updates` extends a sweep (finished or
not) to more updates, as if it had asked for them from the start; `--reuse` takes the methods other
sweeps of the same protocol have finished instead of training them, seed by seed: a method
whose every seed they finished between them (e.g. seeds 0-1 in one sweep and 2-4, `--seed 2
--seeds 3`, in another) is assembled from them. The machinery is experiments.running.sweeps.
"""

from __future__ import annotations

import dataclasses
import sys

from experiments import errors
from experiments.running import devices, flags, sweeps
from experiments import rundir


@dataclasses.dataclass(frozen=True)
class Args(sweeps.Sweep):
    """Train several methods over several seeds and tabulate them as in Table 1."""

    resume: flags.Resume = False
    overwrite: flags.Overwrite = False
    stop_after_chunks: flags.StopAfterChunks = None
    progress: flags.Progress = True
    allow_large: flags.AllowLarge = False


def main(args: Args) -> list[dict] | None:
    """Run (or, with --resume, continue) the sweep (`experiments.running.sweeps.run`);
    returns Table 1's rows (None when stopped by --stop-after-chunks)."""
    flags.check_stop_after_chunks(args.stop_after_chunks, least=0)  # before --resume extends anything
    if args.resume:  # the sweep's own arguments; a flag given that contradicts them is refused
        wanted = args.num_updates  # more updates than the sweep has extend it, once the rest is checked
        args = rundir.resumed_args(
            dataclasses.replace(args, num_updates=None), rundir.SWEEP_FILE, "sweep", keep=flags.INVOCATION
        )
        if wanted is not None:
            extended = sweeps.extend(args.out, wanted, args.allow_large)
            args = dataclasses.replace(args, num_updates=extended.num_updates, reuse=extended.reuse)
    spec = sweeps.Sweep(**{f.name: getattr(args, f.name) for f in dataclasses.fields(sweeps.Sweep)})
    return sweeps.run(
        spec,
        resume=args.resume,
        overwrite=args.overwrite,
        stop_after_chunks=args.stop_after_chunks,
        progress=args.progress,
        allow_large=args.allow_large,
    )


def cli(argv=None) -> None:
    errors.run_cli(Args, main, argv)


def console() -> None:
    """The `foresit-sweep` console script: as `python -m experiments.sweep`."""
    devices.split_host_into_devices()  # before jax starts: faster on a CPU (see experiments.running.devices)
    cli(sys.argv[1:])


if __name__ == "__main__":
    console()
