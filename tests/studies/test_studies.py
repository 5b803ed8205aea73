"""docs/studies.md, each study's home: every path it names exists, every archive in
docs/data/ and every plan in docs/plans/ belongs to exactly one study, and every section
it names is a heading of its doc (GitHub's anchors)."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
COLUMNS = ["study", "question", "plan", "runner", "archives", "data test", "doc section"]


def anchor(heading: str) -> str:
    """GitHub's anchor of a Markdown heading: lower case, punctuation dropped but '-' and
    '_', spaces to '-'."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def studies(text: str) -> dict[str, dict[str, list[str]]]:
    """{study: {column: [the code spans of its cell]}} from the page's one table."""
    rows = [line for line in text.splitlines() if line.startswith("|")]
    header = [c.strip() for c in rows[0].strip("|").split("|")]
    if header != COLUMNS:
        raise ValueError(f"docs/studies.md's columns are {header}, expected {COLUMNS}")
    out = {}
    for row in rows[2:]:
        cells = [c.strip() for c in row.strip("|").split("|")]
        name = cells[0]
        if name in out:
            raise ValueError(f"study {name!r} has two rows")
        out[name] = {col: re.findall(r"`([^`]+)`", cell) for col, cell in zip(COLUMNS, cells)}
        out[name]["runner text"] = [cells[COLUMNS.index("runner")]]
    return out


def test_the_anchor_of_a_heading_is_githubs():
    assert anchor("The paper's question there (5 seeds, 2026-11-27)") == "the-papers-question-there-5-seeds-2026-11-27"
    assert (
        anchor("Channels (issue 68, docs/plans/ceiling_channels.md)") == "channels-issue-68-docsplansceiling_channelsmd"
    )


def test_a_malformed_page_is_refused():
    with pytest.raises(ValueError, match="columns"):
        studies("| study | plan |\n|---|---|\n")
    table = "| " + " | ".join(COLUMNS) + " |\n|" + "---|" * len(COLUMNS) + "\n"
    row = "| a | q | | commands | | | |\n"
    assert set(studies(table + row)) == {"a"}
    with pytest.raises(ValueError, match="two rows"):
        studies(table + row + row)


def test_every_study_has_one_home_and_every_path_it_names_exists():
    found = studies((ROOT / "docs" / "studies.md").read_text())
    assert {"fair", "channels", "ceiling", "replication_3x"} <= set(found)
    missing, claimed = [], {}
    for name, cells in found.items():
        runner = cells["runner"] or cells["runner text"]
        assert runner == ["commands"] or all((ROOT / r).is_file() for r in runner), (name, runner)
        assert cells["data test"], f"{name}: no data test"
        for column in ("plan", "archives", "data test"):
            for path in cells[column]:
                if "/" not in path:  # an archive not made yet, named in words
                    continue
                if not (ROOT / path).is_file():
                    missing.append(f"{name}: {path}")
                if column in ("plan", "archives"):
                    claimed.setdefault(path, []).append(name)
        assert cells["doc section"], f"{name}: no doc section"
        for section in cells["doc section"]:
            doc, _, wanted = section.partition("#")
            headings = [
                anchor(line.lstrip("#")) for line in (ROOT / doc).read_text().splitlines() if line.startswith("#")
            ]
            if wanted not in headings:
                missing.append(f"{name}: no heading {wanted!r} in {doc}")
    assert not missing, missing
    on_disk = {str(p.relative_to(ROOT)) for folder in ("docs/data", "docs/plans") for p in (ROOT / folder).iterdir()}
    assert set(claimed) == on_disk, (sorted(on_disk - set(claimed)), sorted(set(claimed) - on_disk))
    assert all(len(owners) == 1 for owners in claimed.values()), {p: o for p, o in claimed.items() if len(o) > 1}
