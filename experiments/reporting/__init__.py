"""Reporting: statistics, tables, verdicts and figures, and the probes' and the C-VAE
comparison's reports (docs/design.md). The lower layer: it imports nothing of
experiments/running (tests/structure/test_layering.py)."""
