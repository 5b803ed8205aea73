"""The run machinery the programs share: presets, sweeps, the run loop, validation and
selection, run folders, checkpoints, trained models read back (docs/design.md)."""
