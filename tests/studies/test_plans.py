"""A study's plan precedes its runs: every docs/plans/*.md names its archive, and once the
archive is in docs/data, every commit its runs record (run.json's "commits") descends from
the commit that added the plan."""

import json
import subprocess
import tarfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PLANS = sorted((REPO / "docs" / "plans").glob("*.md"))


def git(*args) -> subprocess.CompletedProcess:
    return subprocess.run(["git", "-C", str(REPO), *args], capture_output=True, text=True)


def plan_commit(plan: Path) -> str | None:
    out = git("log", "--diff-filter=A", "--format=%H", "--", str(plan.relative_to(REPO))).stdout.split()
    return out[-1] if out else None


def recorded_commits(archive: Path) -> list[str]:
    with tarfile.open(archive) as tar:
        infos = [m for m in tar.getmembers() if m.name.endswith("run.json")]
        runs = [json.load(tar.extractfile(m)) for m in infos]
    return [c for run in runs for c in run.get("commits", [])]


def test_there_is_a_plan_and_each_names_its_archive():
    assert PLANS
    for plan in PLANS:
        assert any(line.startswith("archive: docs/data/") for line in plan.read_text().splitlines()), plan.name


def archives(plan: Path) -> list[Path]:
    """Every archive a plan names, one `archive: docs/data/...` line each (one per stage)."""
    return [
        REPO / line.split(": ", 1)[1].strip() for line in plan.read_text().splitlines() if line.startswith("archive: ")
    ]


STAGES = [(plan, archive) for plan in PLANS for archive in archives(plan)]


def test_archives_are_read_from_every_archive_line(tmp_path):
    plan = tmp_path / "plan.md"
    plan.write_text("# Plan\n\narchive: docs/data/a.tar.xz\narchive: docs/data/b.tar.xz\n\nnot archive: x\n")
    assert archives(plan) == [REPO / "docs/data/a.tar.xz", REPO / "docs/data/b.tar.xz"]


@pytest.mark.parametrize("plan, archive", STAGES, ids=[f"{p.stem}:{a.name}" for p, a in STAGES])
def test_a_plan_precedes_every_run_of_its_archive(plan, archive):
    if not archive.exists():
        pytest.skip(f"{archive.name}: not run yet")
    if git("rev-parse", "HEAD").returncode != 0:
        pytest.skip("not a git checkout")
    first = plan_commit(plan)
    assert first is not None, f"{plan.name} is not committed"
    commits = recorded_commits(archive)
    assert commits, f"{archive.name}: its run.json files record no commit"
    for commit in commits:
        assert not commit.endswith("+dirty"), f"{archive.name}: a run from uncommitted code ({commit})"
        assert git("merge-base", "--is-ancestor", first, commit).returncode == 0, (
            f"{archive.name}: run at {commit[:7]} does not descend from the plan's commit {first[:7]}"
        )


def test_runs_record_the_commits_that_trained_them(monkeypatch):
    from experiments import rundir

    commit = rundir.code_commit()
    if git("rev-parse", "HEAD").returncode == 0:
        assert commit is not None and commit.split("+")[0] == git("rev-parse", "HEAD").stdout.strip()
    monkeypatch.setattr(rundir, "code_commit", lambda: "b" * 40)
    info = {"arm": "a3c"}
    assert rundir.with_commit(info, None) == {"arm": "a3c", "commits": ["b" * 40]}
    assert rundir.with_commit(info, {"commits": ["a" * 40]})["commits"] == ["a" * 40, "b" * 40]  # resumed elsewhere
    assert rundir.with_commit(info, {"commits": ["b" * 40]})["commits"] == ["b" * 40]  # resumed here: once
    monkeypatch.setattr(rundir, "code_commit", lambda: None)  # an installed wheel: nothing to record
    assert rundir.with_commit(info, {"commits": ["a" * 40]})["commits"] == ["a" * 40]
