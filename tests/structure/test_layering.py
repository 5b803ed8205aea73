"""How the project's modules import each other, read from their source (ast; nothing of the project is
imported but `experiments.rundir`, for the format's names):

* The library (foresit_jax) and the environment (envs) import nothing of experiments or
  benchmarks: the agent is whole without the programs and the studies.
* experiments/reporting (statistics, tables, figures, reports: pure functions of results)
  is the lower layer and imports nothing of experiments/running (the run machinery), which
  imports it: one way only. Both raise `experiments.errors.UserError`, a leaf.
* experiments/analysis (the studies' pure functions over the library: the probes, the C-VAE
  comparison) imports nothing else of experiments, and does no CLI, files or logging.
* An import of the project's own modules sits at the top of its module, where the reader
  sees what a module depends on, unless it defers an optional or heavy dependency or
  breaks an import cycle: those are listed in `ALLOWED`, each with its reason.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PROJECT = ("foresit_jax", "envs", "experiments", "benchmarks")

# The packages whose function-level imports are checked.
CHECKED = ("foresit_jax", "experiments", "benchmarks", "envs")

# (file, function, module imported) -> why it is imported inside the function.
ALLOWED = {
    (
        "experiments/__init__.py",
        "__getattr__",
        "experiments.running",
    ): "defers jax and the library to `experiments.load`: every `python -m experiments.<program>` imports the package",
    (
        "experiments/running/paper_figures.py",
        "trajectories_figure",
        "envs.render",
    ): "defers matplotlib (envs.render imports it at its top) to the figure that draws",
    ("envs/gymnax_compat.py", "make_gymnax", "envs"): "cycle: envs/__init__ imports gymnax_compat",
    ("envs/gymnax_compat.py", "register_gymnax", "envs"): "cycle: envs/__init__ imports gymnax_compat",
    (
        "benchmarks/bench_devices.py",
        "measure",
        "experiments.running",
    ): "defers jax and the trainer: the parent process only starts the measuring ones",
    (
        "benchmarks/bench_devices.py",
        "measure",
        "experiments.running.presets",
    ): "defers jax and the trainer: the parent process only starts the measuring ones",
    (
        "benchmarks/bench_devices.py",
        "measure",
        "foresit_jax.train",
    ): "defers jax and the trainer: the parent process only starts the measuring ones",
    (
        "benchmarks/bench_grid.py",
        "main",
        "experiments.running.presets",
    ): "defers jax and the trainer past the flags (--help, a refused flag)",
    (
        "benchmarks/bench_grid.py",
        "main",
        "foresit_jax.train",
    ): "defers jax and the trainer past the flags (--help, a refused flag)",
}


def modules(package: str, root: Path = ROOT) -> list[Path]:
    return sorted((root / package).rglob("*.py"))


def imports(path: Path, root: Path = ROOT) -> list[tuple[str, str, list[str]]]:
    """(the enclosing function's qualified name, '' at module or class level; the module the
    import statement names; every module it may import) of each import in `path`: `import
    a.b` names a.b; `from a import b` names a, and imports a and perhaps a.b (b may be a
    module). A relative import is resolved against `path`'s package."""
    found = []

    def visit(node, qualname: str, in_function: bool):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = f"{qualname}.{child.name}" if qualname else child.name
                visit(child, name, in_function or not isinstance(child, ast.ClassDef))
                continue
            where = qualname if in_function else ""
            if isinstance(child, ast.Import):
                found.extend((where, alias.name, [alias.name]) for alias in child.names)
            elif isinstance(child, ast.ImportFrom):
                base = child.module or ""
                if child.level:
                    package = path.relative_to(root).parent.parts
                    base = ".".join([*package[: len(package) - (child.level - 1)], *([base] if base else [])])
                found.append((where, base, [base, *(f"{base}.{alias.name}" for alias in child.names)]))
            visit(child, qualname, in_function)

    visit(ast.parse(path.read_text(), str(path)), "", False)
    return found


def layer_imports(lower: str, upper: str, root: Path = ROOT) -> list[str]:
    """'file imports module' for each import of experiments/`upper` by experiments/`lower`."""
    prefix = f"experiments.{upper}"
    return [
        f"{path.relative_to(root)} imports {name}"
        for path in modules(f"experiments/{lower}", root)
        for _, _, names in imports(path, root)
        for name in names
        if name == prefix or name.startswith(prefix + ".")
    ]


def test_reporting_is_below_running():
    """reporting imports nothing of running (and so they do not import each other both ways)."""
    assert layer_imports("reporting", "running") == []
    assert layer_imports("running", "reporting"), "running uses reporting: the layers are as documented"


def project_imports(package: str, root: Path = ROOT) -> list[tuple[str, str]]:
    """(file, module) for each project module (`PROJECT`) that a module of `package` (a
    folder under `root`, e.g. experiments/analysis) may import, at the top or in a function."""
    return [
        (str(path.relative_to(root)), name)
        for path in modules(package, root)
        for _, _, names in imports(path, root)
        for name in names
        if name.split(".")[0] in PROJECT
    ]


def test_the_library_and_the_environment_import_nothing_of_the_programs():
    """foresit_jax and envs import no module of experiments or benchmarks (at the top or in
    a function): the studies' code over the agent lives in experiments/analysis."""
    for package in ("foresit_jax", "envs"):
        found = [(f, m) for f, m in project_imports(package) if m.split(".")[0] in ("experiments", "benchmarks")]
        assert found == [], found


def test_analysis_imports_nothing_else_of_experiments():
    """experiments/analysis is below the programs, running/ and reporting/ (which import it)
    and imports only the library, the environment and itself."""
    found = [
        (f, m)
        for f, m in project_imports("experiments/analysis")
        if m.split(".")[0] not in ("foresit_jax", "envs") and not m.startswith("experiments.analysis")
    ]
    assert found == [], found
    for package in ("experiments/running", "experiments/reporting"):
        assert any(m.startswith("experiments.analysis") for _, m in project_imports(package)), package


# What parses a command line, reads or writes files, logs or prints: none of it in experiments/analysis.
IO_MODULES = ("argparse", "tyro", "logging", "os", "sys", "pathlib", "shutil", "json", "pickle", "csv", "tqdm")
IO_MODULES += ("matplotlib", "orbax")
IO_FUNCTIONS = ("open", "print", "input")
IO_METHODS = ("write_text", "read_text", "write_bytes", "read_bytes", "save", "savez", "load", "savefig")


def io_uses(package: str, root: Path = ROOT) -> list[str]:
    """'file imports module' for each import of `IO_MODULES` (or their submodules) and
    'file:line name' for each call of `IO_FUNCTIONS` or of a method named in `IO_METHODS`
    (`np.save`, `path.write_text`) by a module of `package`."""
    found = []
    for path in modules(package, root):
        where = path.relative_to(root)
        found += [
            f"{where} imports {name}"
            for _, _, names in imports(path, root)
            for name in names
            if name.split(".")[0] in IO_MODULES
        ]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Call) and (
                (isinstance(node.func, ast.Name) and node.func.id in IO_FUNCTIONS)
                or (isinstance(node.func, ast.Attribute) and node.func.attr in IO_METHODS)
            ):
                found.append(f"{where}:{node.lineno} {getattr(node.func, 'id', None) or node.func.attr}")
    return found


def test_analysis_does_no_cli_files_or_logging():
    assert io_uses("experiments/analysis") == []


def test_the_analysis_checks_see_what_they_look_for(tmp_path):
    package = tmp_path / "experiments" / "analysis"
    package.mkdir(parents=True)
    (package / "x.py").write_text(
        "import logging\nfrom pathlib import Path\nfrom experiments.running import models\n"
        "import foresit_jax.train\nfrom experiments.analysis import y\n"
        "def f(p):\n    print(1)\n    Path(p).write_text('x')\n"
    )
    assert sorted(io_uses("experiments/analysis", tmp_path)) == [
        "experiments/analysis/x.py imports logging",
        "experiments/analysis/x.py imports pathlib",
        "experiments/analysis/x.py imports pathlib.Path",
        "experiments/analysis/x.py:7 print",
        "experiments/analysis/x.py:8 write_text",
    ]
    x = "experiments/analysis/x.py"
    assert project_imports("experiments/analysis", tmp_path) == [
        (x, "experiments.running"),
        (x, "experiments.running.models"),
        (x, "foresit_jax.train"),
        (x, "experiments.analysis"),
        (x, "experiments.analysis.y"),
    ]


def test_errors_is_a_leaf():
    """experiments.errors imports nothing of the project: either layer may import it."""
    assert [m for _, m, _ in imports(ROOT / "experiments" / "errors.py") if m.split(".")[0] in PROJECT] == []


def test_rundir_is_a_leaf_beside_errors():
    """The run-folder format (experiments.rundir) imports nothing of the project but
    experiments.errors: the run machinery and the reporting that reads finished folders
    both read the format there."""
    found = {m for _, m, _ in imports(ROOT / "experiments" / "rundir.py") if m.split(".")[0] in PROJECT}
    assert found == {"experiments.errors"}


def format_names_outside(root: Path = ROOT) -> list[str]:
    """'file:line name' for each place outside experiments/rundir.py that spells one of the
    run-folder format's names (`rundir.FORMAT_NAMES`) itself: a string constant that is one
    of them: a file's name anywhere but as a dict key, a folder's name (checkpoints, methods)
    where it is joined onto a path (`folder / "methods"`, `Path(folder, "methods")`,
    `folder.joinpath("methods")`). A name inside a longer text (a message, a docstring) is
    not one."""
    from experiments import rundir

    names = set(rundir.FORMAT_NAMES)
    found = []
    for package in ("experiments", "benchmarks"):
        for path in modules(package, root):
            if path == root / "experiments" / "rundir.py":
                continue
            tree = ast.parse(path.read_text(), str(path))
            keys = {id(k) for node in ast.walk(tree) if isinstance(node, ast.Dict) for k in node.keys}
            joined = {id(n.right) for n in ast.walk(tree) if isinstance(n, ast.BinOp) and isinstance(n.op, ast.Div)}
            joined |= {  # Path(x, "methods"), x.joinpath("methods")
                id(a)
                for n in ast.walk(tree)
                if isinstance(n, ast.Call)
                and (getattr(n.func, "id", None) == "Path" or getattr(n.func, "attr", None) == "joinpath")
                for a in n.args
            }
            for node in ast.walk(tree):
                if not (isinstance(node, ast.Constant) and node.value in names) or id(node) in keys:
                    continue
                if "." in node.value or id(node) in joined:  # a folder's name (methods) only where joined on
                    found.append(f"{path.relative_to(root)}:{node.lineno} {node.value}")
    return found


def test_the_run_folder_format_is_spelled_in_one_module():
    """A run or sweep folder's file names are rundir's constants and path functions; no other
    module of the programs writes `folder / "results.json"`."""
    assert format_names_outside() == []


def test_the_format_check_sees_a_name_spelled_elsewhere(tmp_path):
    (tmp_path / "experiments").mkdir()
    (tmp_path / "benchmarks").mkdir()
    (tmp_path / "experiments" / "rundir.py").write_text('RESULTS = "results.json"\n')
    (tmp_path / "experiments" / "x.py").write_text(
        'def f(folder):\n    """Reads results.json."""\n'
        '    print("no results.json here", ["methods"])\n    d = {"methods": 1, "results.json": 2}\n'
        '    name = "run.json"\n'
        '    Path(folder, "checkpoints"), folder.joinpath("methods"), Path("checkpoints.txt")\n'
        '    return folder / "methods" / "a" / "results.json"\n'
    )
    assert sorted(format_names_outside(tmp_path)) == [
        "experiments/x.py:5 run.json",
        "experiments/x.py:6 checkpoints",
        "experiments/x.py:6 methods",
        "experiments/x.py:7 methods",
        "experiments/x.py:7 results.json",
    ]


def function_level_imports(packages=CHECKED, root: Path = ROOT) -> set[tuple[str, str, str]]:
    """(file, function, module) of each import of a project module made inside a function."""
    return {
        (str(path.relative_to(root)), where, module)
        for package in packages
        for path in modules(package, root)
        for where, module, _ in imports(path, root)
        if where and module.split(".")[0] in PROJECT
    }


def test_function_level_imports_of_the_project_are_only_the_allowed_ones():
    found = function_level_imports()
    new = sorted(found - set(ALLOWED))
    assert new == [], "move these imports to the top of their module, or add them to ALLOWED with why"
    assert sorted(set(ALLOWED) - found) == [], "these ALLOWED imports are gone: take them out of the list"
    assert all(reason.strip() for reason in ALLOWED.values())


def test_the_checks_see_what_they_look_for(tmp_path):
    """The ast walk finds a function's import (a method's and a nested function's too),
    resolves a relative one, and counts a class body's as the module's."""
    package = tmp_path / "experiments" / "reporting"
    package.mkdir(parents=True)
    (package / "x.py").write_text(
        "import experiments.running.run\n"
        "def f():\n    from ..running import sweeps\n"
        "class C:\n    from envs import catalog\n"
        "    def g(self):\n        def h():\n"
        "            import foresit_jax.train\n"
    )
    assert imports(package / "x.py", tmp_path) == [
        ("", "experiments.running.run", ["experiments.running.run"]),
        ("f", "experiments.running", ["experiments.running", "experiments.running.sweeps"]),
        ("", "envs", ["envs", "envs.catalog"]),
        ("C.g.h", "foresit_jax.train", ["foresit_jax.train"]),
    ]
    assert len(layer_imports("reporting", "running", tmp_path)) == 3
    x = "experiments/reporting/x.py"
    assert function_level_imports(("experiments",), tmp_path) == {
        (x, "f", "experiments.running"),
        (x, "C.g.h", "foresit_jax.train"),
    }
