"""The docs' generated blocks, one module a page (docs/ceiling.md's in `ceiling_md`): each module's `BLOCKS` maps a block's name
to (the file that holds it, a function of `registry.Archives` giving the block's text).
`experiments.regenerate` writes them between the file's markers; `BLOCKS` here is all of
them (a name defined twice is refused). What the pages share, the formats and the Holm
families, is `common` (no page of its own); what they read, `registry.Archives`."""

from __future__ import annotations

from typing import Callable

from experiments.reporting.pages import (
    ceiling_md,
    foresight_md,
    houses_md,
    priors_md,
    readme_md,
    results_md,
    studies_md,
    targets_md,
)
from experiments.reporting.registry import Archives

Block = tuple[str, Callable[[Archives], str]]
PAGES = (readme_md, studies_md, results_md, ceiling_md, priors_md, houses_md, foresight_md, targets_md)


def _gathered() -> dict[str, Block]:
    out: dict[str, Block] = {}
    for page in PAGES:
        for name, block in page.BLOCKS.items():
            if name in out:
                raise ValueError(f"generated block {name!r} is defined twice ({page.__name__} and another page)")
            out[name] = block
    return out


BLOCKS: dict[str, Block] = _gathered()
