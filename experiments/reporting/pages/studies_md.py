"""docs/studies.md's generated block: the studies' table (`registry.STUDIES`)."""

from __future__ import annotations

from experiments.reporting.registry import studies_table

BLOCKS = {"studies": ("docs/studies.md", lambda archives: studies_table())}
