"""The run machinery the programs share: presets, the run flags, sweeps, the run loop,
validation and selection, checkpoints, trained models read back, the probes run over
them and the paper report (docs/design.md). Above experiments/reporting, which it imports;
both read and write run folders through `experiments.rundir`."""
