"""The run machinery the programs share: presets, the run flags, sweeps, the run loop,
validation and selection, run folders, checkpoints, trained models read back and the
probes run over them (docs/design.md). Above experiments/reporting, which it imports."""
