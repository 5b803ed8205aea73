"""README.md's generated block: the Results table (`registry.README_COMPARISONS`)."""

from __future__ import annotations

from experiments.reporting.registry import README_COMPARISONS, Archives, comparisons_table


def readme_results(archives: Archives) -> str:
    return comparisons_table(README_COMPARISONS, archives)


BLOCKS = {"readme-results": ("README.md", readme_results)}
