"""experiments/ by role (docs/design.md's layout): the programs are thin and none imports
another; the machinery (running/), the reporting (reporting/) and the studies' functions
(analysis/) import no program; the console scripts are programs; a sweep resumed as another
sweep is refused before anything runs."""

import ast
import dataclasses
import tomllib
from pathlib import Path

import pytest

from experiments import errors
from experiments.running import sweeps
from experiments import rundir

REPO = Path(__file__).resolve().parents[2]
PACKAGE = REPO / "experiments"
# Every module of experiments/ is a program but the two leaves the programs, the machinery and the reporting
# all import (tests/structure/test_layering.py): `errors`, which they raise from, and `rundir`, the run-folder format.
LEAVES = ("errors", "rundir")
PROGRAMS = sorted(p.stem for p in PACKAGE.glob("*.py") if p.stem not in ("__init__", *LEAVES))


def imported_modules(path: Path) -> set[str]:
    """Every module `path` imports, at the top or inside a function: `from experiments
    import a` counts as `experiments.a` (a module, or a name of the package)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            found.add(node.module)
            found |= {f"{node.module}.{a.name}" for a in node.names}
    return found


def test_the_helper_sees_imports_inside_functions(tmp_path):
    source = tmp_path / "m.py"
    source.write_text(
        "import os\ndef f():\n    from experiments import sweep, tune\n    import experiments.paper as p\n"
    )
    assert {"os", "experiments.sweep", "experiments.tune", "experiments.paper"} <= imported_modules(source)


def test_the_programs_are_the_modules_of_experiments_and_the_console_scripts_point_at_them():
    assert {"train", "evaluate", "sweep", "tune", "paper", "probe", "failures", "compare"} <= set(PROGRAMS)
    scripts = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["scripts"]
    for name, target in scripts.items():
        module = target.split(":")[0]
        assert module.startswith("experiments.") and module.split(".")[1] in PROGRAMS and module.count(".") == 1, name


@pytest.mark.parametrize("program", PROGRAMS)
def test_no_program_imports_another(program):
    others = {f"experiments.{p}" for p in PROGRAMS if p != program}
    assert not imported_modules(PACKAGE / f"{program}.py") & others


@pytest.mark.parametrize("package", ["running", "reporting", "analysis"])
def test_the_machinery_and_the_reporting_import_no_program(package):
    programs = {f"experiments.{p}" for p in PROGRAMS}
    for path in (PACKAGE / package).glob("*.py"):
        assert not imported_modules(path) & programs, path
    if package == "reporting":  # the reporting reads results; it never runs a sweep
        for path in (PACKAGE / package).glob("*.py"):
            assert "experiments.running.sweeps" not in imported_modules(path), path


def test_a_sweep_continued_as_another_sweep_is_refused_before_anything_runs(tmp_path):
    """`sweeps.run(spec, resume=True)` (as tune and paper continue their sweeps) checks the
    folder was started as `spec`; the program's --resume takes the saved arguments instead."""
    started = sweeps.Sweep(methods=("a3c",), seeds=2, preset="tiny", out=tmp_path / "s")
    (tmp_path / "s").mkdir()
    rundir.write_started_args(tmp_path / "s" / "sweep.json", started, ())
    assert sweeps.saved(tmp_path / "s") == dataclasses.replace(started, out=tmp_path / "s")
    other = dataclasses.replace(started, seeds=3, num_updates=7)
    with pytest.raises(errors.UserError, match=r"started as another sweep \(its seeds, num_updates differ\)"):
        sweeps.run(other, resume=True, progress=False)
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == [rundir.LOCK_FILE, "sweep.json"]
