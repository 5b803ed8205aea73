"""Every test file the project cites is there: each `tests/...py` path in the README, the docs
(docs/studies.md and the plans included), the CHANGELOG's Unreleased part, .ci/run,
pyproject.toml and the docstrings and comments of the code and the tests, and each study's
data test in the registry (`experiments.reporting.registry.STUDIES`).  A test moved or
renamed without its citations fails here.  (The CHANGELOG's released parts keep the paths
of their day.)"""

import re
from pathlib import Path

from experiments.reporting import registry

REPO = Path(__file__).resolve().parents[2]
CITED = re.compile(r"tests/[\w/]*\.py")
CODE_FOLDERS = ("envs", "foresit_jax", "experiments", "benchmarks", "examples", "scripts", "tests")


def unreleased(changelog: str) -> str:
    """The CHANGELOG's part above its first release."""
    start = changelog.index("## Unreleased")
    return changelog[start : changelog.index("\n## ", start + 1)]


def cited_texts() -> dict[str, str]:
    """{file: the text whose test paths must exist}."""
    texts = {"CHANGELOG.md (Unreleased)": unreleased((REPO / "CHANGELOG.md").read_text())}
    files = [REPO / "README.md", REPO / ".ci" / "run", REPO / "pyproject.toml", *sorted((REPO / "docs").rglob("*.md"))]
    for folder in CODE_FOLDERS:
        files += sorted((REPO / folder).rglob("*.py")) + sorted((REPO / folder).rglob("*.sh"))
    for path in files:
        texts[str(path.relative_to(REPO))] = path.read_text()
    return texts


def test_the_pattern_finds_test_paths_and_nothing_else():
    text = "tests/envs/test_oracle.py, (tests/conftest.py) and `tests/agent/test_lstm.py::test_x`; tests/data/x.npz"
    assert CITED.findall(text) == ["tests/envs/test_oracle.py", "tests/conftest.py", "tests/agent/test_lstm.py"]
    assert unreleased("# C\n\n## Unreleased\n\nnew\n\n## 0.1.0\n\nold\n") == "## Unreleased\n\nnew\n"


def test_every_cited_test_path_exists():
    texts = cited_texts()
    assert "README.md" in texts and "docs/testing.md" in texts and "docs/studies.md" in texts
    missing = sorted(
        f"{name}: {path}"
        for name, text in texts.items()
        for path in set(CITED.findall(text))
        if not (REPO / path).is_file()
    )
    assert not missing, missing


def test_every_studys_data_test_exists():
    assert registry.STUDIES
    missing = [f"{s.name}: {s.data_test}" for s in registry.STUDIES if not (REPO / s.data_test).is_file()]
    assert not missing, missing
    assert all(CITED.fullmatch(s.data_test) for s in registry.STUDIES)
