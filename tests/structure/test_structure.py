"""The shape of the foresit_jax package, read from its source (ast) and, for the lazy face,
from a fresh interpreter (issue 60; docs/design.md):

* at most 7 import floors (`MAX_FLOORS`; a module with no import of the package is on floor
  1; one that imports modules of floor k at most is on floor k + 1), the package's __init__
  importing none of its modules at load (its names load lazily);
* methods.py imports nothing of the package and config.py only methods.py, so a Config,
  a record of hyperparameters, pulls in neither jax nor the algorithm;
* no class has more than 12 methods (`MAX_METHODS`, every function its body defines:
  `__init__`, properties, cached properties and static methods count), and no acting entry
  point takes more than 8 parameters (`MAX_ACTING_PARAMETERS`);
* a method's pieces become modules in one place (`networks.build`);
* imagination.py, ForeSIT's one home, imports of the package only the leaves below it
  (`IMAGINATION_IMPORTS`: layers, methods), never a module that calls into it
  (networks hands it an `Imagination` record instead).
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[2] / "foresit_jax"
MAX_FLOORS = 7  # policy (the step) and maml (the base that builds on it) sit above rollout: docs/design.md
MAX_METHODS = 12  # the Trainer's 12 (0.3.0 counted 10, leaving out __init__ and run_seeds)
MAX_ACTING_PARAMETERS = 8
IMAGINATION_IMPORTS = {"layers", "methods"}  # and envs.wrappers, outside the package


def _tree(name: str) -> ast.Module:
    return ast.parse((PACKAGE / f"{name}.py").read_text())


def _modules() -> list[str]:
    return sorted(p.stem for p in PACKAGE.glob("*.py") if p.stem != "__init__")


def package_imports(tree: ast.Module) -> set[str]:
    """The package's modules a module imports at its top level (not inside functions)."""
    found = set()
    for node in tree.body:
        if isinstance(node, ast.Import):
            found |= {a.name.split(".")[1] for a in node.names if a.name.startswith("foresit_jax.")}
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "foresit_jax":
            if node.module == "foresit_jax":
                found |= {a.name for a in node.names}
            else:
                found.add(node.module.split(".")[1])
    return found


def floors(graph: dict[str, set[str]]) -> dict[str, int]:
    out: dict[str, int] = {}

    def floor(name, path=()):
        if name in path:
            raise AssertionError(f"import cycle: {' -> '.join(path + (name,))}")
        if name not in out:
            out[name] = 1 + max((floor(d, path + (name,)) for d in graph[name]), default=0)
        return out[name]

    for name in graph:
        floor(name)
    return out


def test_floors_are_computed_as_documented():
    """The floor function on a hand-made graph (so that the package's test can fail)."""
    graph = {"a": set(), "b": {"a"}, "c": {"a", "b"}, "d": {"c"}}
    assert floors(graph) == {"a": 1, "b": 2, "c": 3, "d": 4}
    with pytest.raises(AssertionError, match="cycle"):
        floors({"a": {"b"}, "b": {"a"}})


def test_the_package_is_at_most_seven_floors_deep():
    graph = {m: package_imports(_tree(m)) for m in _modules()}
    found = floors(graph)
    assert max(found.values()) <= MAX_FLOORS, sorted(found.items(), key=lambda kv: kv[1])
    assert package_imports(_tree("__init__")) == set(), "the package face imports its modules lazily"


def test_imagination_imports_only_the_leaves_below_it():
    graph = {m: package_imports(_tree(m)) for m in _modules()}
    assert graph["imagination"] <= IMAGINATION_IMPORTS, graph["imagination"]
    below = set().union(*(graph[m] for m in IMAGINATION_IMPORTS)) | IMAGINATION_IMPORTS
    assert "imagination" not in below, "a module imagination imports imports it back"
    callers = {m for m, deps in graph.items() if "imagination" in deps}
    assert {"networks", "rollout", "train"} <= callers  # what calls into it (the check sees imports)


def test_methods_import_nothing_of_the_package_and_config_only_methods():
    assert package_imports(_tree("methods")) == set()
    assert package_imports(_tree("config")) == {"methods"}


def test_importing_config_loads_neither_jax_nor_the_algorithm():
    code = (
        "import sys; import foresit_jax.config; "
        "print(sorted(m for m in sys.modules if m.startswith('foresit_jax')), 'jax' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "['foresit_jax', 'foresit_jax.config', 'foresit_jax.methods'] False"


def test_the_package_face_loads_names_on_first_use():
    code = (
        "import foresit_jax, sys; "
        "from foresit_jax import evaluate_policy, make_train, Config; "
        "print(evaluate_policy.__module__, make_train.__module__, Config.__module__, "
        "sorted(set(foresit_jax.__all__) - set(dir(foresit_jax))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "foresit_jax.evaluate foresit_jax.train foresit_jax.config []"


@pytest.mark.parametrize(
    "before",
    [
        "",
        "import foresit_jax",
        "from foresit_jax import evaluate_policy, make_act",
        "import foresit_jax.evaluate",
        "from foresit_jax.evaluate import evaluate",
        "from foresit_jax import *",
    ],
)
def test_foresit_jax_evaluate_is_the_module_whatever_was_imported_before(before):
    """`foresit_jax.evaluate` is the module, never its function `evaluate`: by either form
    of import, after any other import of the package."""
    code = (
        f"{before}\nimport types\nimport foresit_jax.evaluate as E\nfrom foresit_jax import evaluate as F\n"
        "import foresit_jax\n"
        "print(all(isinstance(m, types.ModuleType) and m.__name__ == 'foresit_jax.evaluate' "
        "for m in (E, F, foresit_jax.evaluate)), callable(E.evaluate))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "True True", (before, out)


def _counted_methods(cls: ast.ClassDef) -> list[str]:
    """Every function a class's body defines: methods, `__init__` and other dunders,
    properties, cached properties, static and class methods."""
    return [node.name for node in cls.body if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))]


def test_the_count_takes_in_init_and_properties():
    cls = ast.parse(
        "class A:\n    def __init__(self): ...\n    @property\n    def p(self): ...\n"
        "    @functools.cached_property\n    def c(self): ...\n    @staticmethod\n    def s(): ...\n    x = 1\n"
    ).body[0]
    assert _counted_methods(cls) == ["__init__", "p", "c", "s"]


def test_no_class_has_more_than_twelve_methods():
    crowded = {}
    for module in _modules():
        for node in ast.walk(_tree(module)):
            if isinstance(node, ast.ClassDef) and len(_counted_methods(node)) > MAX_METHODS:
                crowded[f"{module}.{node.name}"] = _counted_methods(node)
    assert not crowded


def _parameters(fn: ast.FunctionDef) -> int:
    a = fn.args
    return len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + bool(a.vararg) + bool(a.kwarg)


def test_acting_entry_points_take_at_most_eight_parameters():
    wide = {}
    for module in ("rollout", "policy", "maml"):
        for node in _tree(module).body:
            if isinstance(node, ast.FunctionDef) and not node.name.startswith("_"):
                if _parameters(node) > MAX_ACTING_PARAMETERS:
                    wide[f"{module}.{node.name}"] = _parameters(node)
    assert not wide
    defined = {m: {n.name for n in _tree(m).body if isinstance(n, ast.FunctionDef)} for m in ("rollout", "maml")}
    assert {"act_window", "rollout", "start"} <= defined["rollout"] and {"act", "policy"} <= defined["maml"]


def test_pieces_become_modules_in_networks_build_alone():
    """The agent's network, f_w, ORG's object graph and SAVN's learned loss are made (called)
    only in networks.py (the C-VAE comparison makes its own f_w outside the library, in
    experiments/analysis/cvae.py)."""
    makers = {"ObjectGraph", "LearnedLoss", "ActorCritic", "ImaginationNet"}
    made = {}
    for module in _modules():
        for node in ast.walk(_tree(module)):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in makers:
                made.setdefault(node.func.id, set()).add(module)
    assert made == {name: {"networks"} for name in makers}


def _stem(name: str) -> str:
    """A module's name without a plural's ending (probes -> probe, boxes -> box; progress stays)."""
    if name.endswith(("sses", "shes", "ches", "xes")):
        return name[:-2]
    if name.endswith("s") and not name.endswith("ss"):
        return name[:-1]
    return name


def test_no_two_modules_share_a_stem_or_its_plural():
    """Inside foresit_jax/ and experiments/ (the CLIs, top-level modules with a `__main__`
    guard, apart: their names are the commands), no two modules share a stem or its plural."""
    root = PACKAGE.parent
    cli = {p for p in (root / "experiments").glob("*.py") if '__name__ == "__main__"' in p.read_text()}
    modules = [
        p
        for folder in ("foresit_jax", "experiments")
        for p in (root / folder).rglob("*.py")
        if p.name != "__init__.py" and p not in cli
    ]
    assert len(modules) > 30 and len(cli) >= 10
    by_stem = {}
    for path in modules:
        by_stem.setdefault(_stem(path.stem), []).append(str(path.relative_to(root)))
    assert not {s: p for s, p in by_stem.items() if len(p) > 1}
    assert _stem("probes") == _stem("probe") and _stem("sweeps") == _stem("sweep") and _stem("boxes") == "box"
    assert _stem("stats") == "stat" and _stem("tuning") == "tuning" and _stem("progress") == "progress"


def test_the_citation_and_the_changelog_name_the_packages_version():
    """A released version (pyproject.toml's, not a .dev one, which cites the last release) is
    CITATION.cff's and has its CHANGELOG section ("## 0.3.0 (...)"), so a release cannot
    leave either behind."""
    import re
    import tomllib

    root = Path(__file__).resolve().parents[2]
    version = tomllib.loads((root / "pyproject.toml").read_text())["project"]["version"]
    if ".dev" in version:
        pytest.skip(f"{version} is a development version")
    cited = re.search(r"^version: (\S+)$", (root / "CITATION.cff").read_text(), re.M)
    assert cited is not None and cited.group(1) == version
    assert re.search(rf"^## {re.escape(version)} \(", (root / "CHANGELOG.md").read_text(), re.M)
