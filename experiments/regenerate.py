"""Regenerate the docs' generated blocks from the archives: `python -m experiments.regenerate`
rewrites, between each block's markers, what `experiments.reporting.pages.BLOCKS` makes
of docs/data's archives (the studies' table, the README's Results, ...); `--check` writes
nothing and exits 1, naming each block that differs (the drift test runs it). Prose outside
the markers is the authors'; inside them, the pages' (from the registry's data).

    <!-- generated: NAME (python -m experiments.regenerate; edit experiments/reporting/pages/, not this block) -->
    ...
    <!-- end generated: NAME -->
"""

from __future__ import annotations

import dataclasses
import difflib
import re
import sys
from pathlib import Path

from experiments import errors
from experiments.reporting import pages, registry

START = (
    "<!-- generated: {name} (python -m experiments.regenerate; edit experiments/reporting/pages/, not this block) -->"
)
END = "<!-- end generated: {name} -->"
_BLOCK = re.compile(r"<!-- generated: (?P<name>[\w-]+) .*?-->\n(?P<body>.*?)<!-- end generated: (?P=name) -->", re.S)


@dataclasses.dataclass(frozen=True)
class Args:
    """Rewrite the docs' generated blocks from docs/data's archives (or, with --check, say which differ)."""

    check: bool = False
    """Write nothing; exit 1 naming each block that differs from what the archives give."""
    root: Path = registry.ROOT
    """The checkout whose docs (and docs/data) are read."""


def blocks_of(text: str) -> dict[str, str]:
    """{name: body} of the generated blocks in `text`."""
    return {m["name"]: m["body"] for m in _BLOCK.finditer(text)}


def rendered(name: str, body: str) -> str:
    return START.format(name=name) + "\n" + body + END.format(name=name)


def regenerate(root: Path = registry.ROOT, archives: registry.Archives | None = None) -> dict[str, tuple[str, str]]:
    """{file: (its text now, its text with every block regenerated)} for each file that holds
    a block of `pages.BLOCKS`. A block whose markers are missing from its
    file, or markers naming no block of the pages, are a UserError."""
    archives = archives or registry.Archives(root / "docs" / "data")
    for path in [root / "README.md", *sorted((root / "docs").rglob("*.md"))]:  # before any block is made
        unknown = set(blocks_of(path.read_text())) - set(pages.BLOCKS)
        if unknown:
            raise errors.UserError(f"{path.relative_to(root)}: markers of unknown block(s) {sorted(unknown)}")
    by_file: dict[str, list[str]] = {}
    for name, (file, _) in pages.BLOCKS.items():
        by_file.setdefault(file, []).append(name)
    out = {}
    for file, names in by_file.items():
        text = (root / file).read_text()
        found = blocks_of(text)
        missing = [n for n in names if n not in found]
        if missing:
            raise errors.UserError(
                f"{file} has no markers for block(s) {', '.join(missing)}: add "
                f"{START.format(name=missing[0])!r} and {END.format(name=missing[0])!r} where it goes"
            )
        new = text
        for name in names:
            body = pages.BLOCKS[name][1](archives)
            new = _BLOCK.sub(lambda m: rendered(name, body) if m["name"] == name else m[0], new)
        out[file] = (text, new)
    return out


def main(args: Args, archives: registry.Archives | None = None) -> list[str]:
    """The files whose blocks differ (written unless --check); `archives`: those already read."""
    changed = []
    for file, (old, new) in regenerate(args.root, archives).items():
        if old == new:
            continue
        changed.append(file)
        if args.check:
            diff = difflib.unified_diff(
                old.splitlines(), new.splitlines(), f"{file} (now)", f"{file} (regenerated)", lineterm=""
            )
            print("\n".join(diff))
        else:
            (args.root / file).write_text(new)
    if args.check and changed:
        print(f"drift: {', '.join(changed)} differ from the archives; run python -m experiments.regenerate")
    elif args.check:
        print("no drift: every generated block is what the archives give")
    else:
        print(f"regenerated: {', '.join(changed) or 'nothing changed'}")
    return changed


def cli(argv=None) -> None:
    """The command: exit 1 with --check where a block differs, 2 on a refusal."""
    changed = errors.run_cli(Args, main, argv)
    sys.exit(1 if changed and "--check" in (sys.argv[1:] if argv is None else argv) else 0)


if __name__ == "__main__":
    cli()
