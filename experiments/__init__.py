"""The programs that train, evaluate and report (one module per console script:
`python -m experiments.<name>`), beside the machinery they share:

experiments/            the programs: train, evaluate, sweep, tune, paper, compare, probe,
                        failures, foresight, demo, cvae_compare (none imports another)
experiments/running/    the run machinery: presets, sweeps (a sweep's spec and run), the
                        run loop, selection, run folders, checkpoints, trained models
experiments/reporting/  statistics, tables, figures, the probes' and the C-VAE's reports
"""
