"""The docs' generated blocks are what the archives give (`python -m experiments.regenerate
--check`, the drift test), and the generator refuses markers it cannot fill."""

import shutil

import pytest

from experiments import errors, regenerate
from experiments.reporting import registry
from experiments.reporting.pages import targets_md

ROOT = registry.ROOT


@pytest.fixture(scope="module")
def archives():
    return registry.Archives()  # one read of each archive for the module


def test_every_generated_block_is_what_the_archives_give(archives):
    drifted = [file for file, (old, new) in regenerate.regenerate(ROOT, archives).items() if old != new]
    assert not drifted, f"{drifted} differ from the archives: run python -m experiments.regenerate"


def copy_of_the_docs(tmp_path):
    """A checkout's README, docs/*.md and docs/data (linked) in `tmp_path`."""
    shutil.copy(ROOT / "README.md", tmp_path / "README.md")
    (tmp_path / "docs").mkdir()
    for page in (ROOT / "docs").glob("*.md"):
        shutil.copy(page, tmp_path / "docs" / page.name)
    (tmp_path / "docs" / "data").symlink_to(ROOT / "docs" / "data")
    return tmp_path


def test_a_figure_changed_by_hand_is_drift_and_is_put_back(tmp_path, capsys, archives):
    root = copy_of_the_docs(tmp_path)
    readme = (root / "README.md").read_text()
    assert "| +26.3 [+21.7, +30.9] | helps |" in readme
    (root / "README.md").write_text(
        readme.replace("| +26.3 [+21.7, +30.9] | helps |", "| +26.3 [+21.7, +30.9] | level |")
    )
    assert regenerate.main(regenerate.Args(check=True, root=root), archives) == ["README.md"]
    assert "drift: README.md" in capsys.readouterr().out
    assert (root / "README.md").read_text() != readme  # --check writes nothing
    assert regenerate.main(regenerate.Args(root=root), archives) == ["README.md"]
    assert (root / "README.md").read_text() == readme


def test_markers_the_registry_cannot_fill_are_refused(tmp_path, archives):
    root = copy_of_the_docs(tmp_path)
    studies = (root / "docs" / "studies.md").read_text()
    (root / "docs" / "studies.md").write_text(studies.replace("<!-- end generated: studies -->", ""))
    with pytest.raises(errors.UserError, match="docs/studies.md has no markers for block"):
        regenerate.regenerate(root, archives)
    (root / "docs" / "studies.md").write_text(studies)
    extra = regenerate.rendered("no-such-block", "x\n")
    (root / "docs" / "usage.md").write_text((root / "docs" / "usage.md").read_text() + "\n" + extra + "\n")
    with pytest.raises(errors.UserError, match="unknown block"):
        regenerate.regenerate(root, archives)


def test_a_comparison_reads_its_seeds_in_pairs(archives):
    c = registry.README_COMPARISONS[1]
    d = c.differences(archives)
    a, b = archives.results(c.archive, c.a), archives.results(c.archive, c.b)
    assert len(d) == 5 and [r["seed"] for r in a] == [r["seed"] for r in b] == [0, 1, 2, 3, 4]
    assert d[0] == pytest.approx(b[0]["selected"]["overall"]["SR"] - a[0]["selected"]["overall"]["SR"])  # in %
    with pytest.raises(KeyError, match="holds no arm"):
        archives.results(c.archive, "a3c+nothing")


def test_the_targets_pilots_table_from_a_hand_made_archive(tmp_path):
    import json
    import tarfile

    def seed(s, curve, labelled):
        validation = [{"update": u, "SR": sr} for u, sr in curve]
        return {"seed": s, "validation": validation, "diagnostics": {"charts/aux_labelled_fraction": labelled}}

    arms = {
        "a3c@aux_target=compass,aux_weight=0.1": [seed(10, [(500, 10.0), (1000, 30.0)], [1.0, 1.0])],  # area 20
        "a3c@aux_target=compass,aux_weight=1.0": [seed(10, [(500, 10.0), (1000, 20.0)], [1.0, 1.0])],  # area 15
        "a3c@aux_target=success,aux_weight=0.1": [seed(10, [(500, 5.0), (1000, 5.0)], [0.05, 0.15])],  # area 5
        "a3c@aux_target=success,aux_weight=1.0": [seed(10, [(500, 5.0), (1000, 5.0)], [0.1, 0.2])],  # a tie: 1.0
    }
    for arm, results in arms.items():
        folder = tmp_path / "pilot" / "methods" / arm
        folder.mkdir(parents=True)
        (folder / "results.json").write_text(json.dumps({"results": results}))
    (tmp_path / "data").mkdir()
    with tarfile.open(tmp_path / "data" / "targets_pilot.tar.xz", "w:xz") as tar:
        tar.add(tmp_path / "pilot", arcname="pilot")
    rows = targets_md.targets_pilot(registry.Archives(tmp_path / "data")).splitlines()[2:]
    assert rows == [
        "| compass | 0.1 | 20.0 | 20.0 | 100.0% | **chosen** |",
        "| compass | 1 | 15.0 | 15.0 | 100.0% |  |",
        "| success | 0.1 | 5.0 | 5.0 | 10.0% |  |",
        "| success | 1 | 5.0 | 5.0 | 15.0% | **chosen** |",
    ]
