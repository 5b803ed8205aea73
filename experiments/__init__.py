"""The programs that train, evaluate and report (one module per console script:
`python -m experiments.<name>`), beside the machinery they share:

experiments/            the programs: train, evaluate, sweep, tune, paper, compare, probe,
                        failures, foresight, demo, cvae_compare (none imports another);
                        and two leaves every layer imports: errors, the one-line user
                        errors, and rundir, the run-folder format
experiments/running/    the run machinery: presets, the run flags, sweeps (a sweep's spec
                        and run), the run loop, selection, checkpoints, trained models,
                        the probes run over them and the paper report
experiments/reporting/  statistics, tables, figures, the probes' and the C-VAE's reports:
                        below running/, which imports it, never the other way
experiments/analysis/   the studies' pure functions over the library (the probes of i_tau,
                        the C-VAE comparison): below both, importing nothing of experiments

`experiments.load(run_dir, seed=0, which="best")` gives a trained policy to act with in a
user's own code (docs/extending.md).
"""


def __getattr__(name: str):
    """`experiments.load` (a trained policy from a run folder, `running.models.load`),
    imported on first use: `python -m experiments.<program>` does not load it."""
    if name in ("load", "Policy"):
        from experiments.running import models  # deferred: jax and the library, for this name alone

        return getattr(models, name)
    raise AttributeError(f"module 'experiments' has no attribute {name!r}")


def __dir__() -> list[str]:
    """The module's names and the lazily imported ones, so tab completion finds `load`."""
    return sorted(set(globals()) | {"load", "Policy"})
