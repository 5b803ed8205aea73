"""docs/ceiling.md's generated blocks: none yet (its tables are written by hand; issue 81 moves them here)."""

from __future__ import annotations

BLOCKS: dict = {}
