"""Reporting: statistics, tables, verdicts and figures, and the probes' and the C-VAE
comparison's reports (docs/design.md)."""
