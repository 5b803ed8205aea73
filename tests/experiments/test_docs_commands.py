"""Every command of the README and the docs parses, the README's and docs/usage.md's run at a
tiny size, their Python blocks and docs/extending.md's run, and each console script is its
module's program."""

import dataclasses
import importlib
import importlib.util
import json
import os
import re
import shlex
import sys
from pathlib import Path

import jax
import numpy as np
import pytest
import tyro

import train_helpers as H
from cli_helpers import csv_rows
from experiments import evaluate as evaluate_cli
from experiments import sweep
from experiments import train as train_cli
from experiments import rundir

REPO = Path(__file__).resolve().parents[2]

# Cheap in-process CLI calls for every test of this module (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("cheap_experiments")


README = (REPO / "README.md").read_text()


USAGE = (REPO / "docs" / "usage.md").read_text()  # the README's command line, environment and methods


BLOCKS = re.findall(r"```(\w+)\n(.*?)```", README, flags=re.S)


USAGE_BLOCKS = re.findall(r"```(\w+)\n(.*?)```", USAGE, flags=re.S)


CLI_MODULES = {
    "experiments.train": train_cli,
    "experiments.evaluate": evaluate_cli,
    "experiments.sweep": sweep,
    "experiments.probe": importlib.import_module("experiments.probe"),
    "experiments.failures": importlib.import_module("experiments.failures"),
}


# Benchmarks the README documents: their flags must parse (they run in their own tests or
# take minutes by design).
BENCH_ARGS = {  # commands whose flags are parsed here and which run in their own tests
    "benchmarks.bench_train": lambda: importlib.import_module("benchmarks.bench_train").BenchConfig,
    "benchmarks.bench_learning": lambda: importlib.import_module("benchmarks.bench_learning").BenchLearning,
    "experiments.cvae_compare": lambda: importlib.import_module("experiments.cvae_compare").Args,
    "experiments.paper": lambda: importlib.import_module("experiments.paper").Args,  # test_paper.py runs it
    "experiments.demo": lambda: importlib.import_module("experiments.demo").DemoConfig,
    "benchmarks.bench_env": lambda: importlib.import_module("benchmarks.bench_env").BenchConfig,
    "experiments.compare": lambda: importlib.import_module("experiments.compare").Args,  # test_compare.py
    "experiments.tune": lambda: importlib.import_module("experiments.tune").Args,  # test_tune.py runs it
    "experiments.foresight": lambda: importlib.import_module("experiments.foresight").Args,  # test_foresight.py
    "benchmarks.reference_ppo": lambda: (
        importlib.import_module("benchmarks.reference_ppo").Args
    ),  # tests/benchmarks/test_reference_ppo.py
}


DOCS = {path.name: path.read_text() for path in sorted((REPO / "docs").glob("*.md"))}


def readme_commands(text: str = README) -> list[list[str]]:
    """Every `python -m experiments.X ...` of the bash blocks of `text` (the README's by
    default), as argv lists (a line ending in a backslash continues on the next)."""
    commands = []
    for lang, body in re.findall(r"```(\w+)\n(.*?)```", text, flags=re.S):
        if lang != "bash":
            continue
        for line in body.replace("\\\n", " ").splitlines():
            for part in line.split("&&"):
                if "python -m" not in part:  # `git clone <this repository's URL> ...`: not shell-quoted
                    continue
                words = shlex.split(part, comments=True)
                if words[:2] == ["python", "-m"] and words[2].startswith(("experiments.", "benchmarks.")):
                    commands.append(words[2:])
    return commands


def test_readme_commands_parse():
    """Every documented experiments command (code blocks and inline) names a module that
    exists, and the flags of the train/evaluate/sweep ones are accepted. The README and
    docs/usage.md, where its command line went, show every CLI between them."""
    commands = readme_commands()
    assert {c[0] for c in commands + readme_commands(USAGE)} >= set(CLI_MODULES)
    for module, *argv in commands:
        parser = CLI_MODULES[module].Args if module in CLI_MODULES else BENCH_ARGS[module]()
        args = tyro.cli(parser, args=argv)
        assert dataclasses.is_dataclass(args)
    for module in set(re.findall(r"python -m ((?:experiments|benchmarks)\.\w+)", README)):
        assert importlib.util.find_spec(module) is not None, module
    for link in re.findall(r"\]\(((?!https?:)[^)#]+)\)", README):  # relative links and the picture exist
        assert (REPO / link).exists(), link


def test_the_readmes_first_run_is_the_tiny_one_and_its_snippet_acts():
    """A newcomer's first run takes seconds (`--preset tiny`), then the quick one; the
    library snippet ends with the trained policy in memory (`make_act`, issue 71)."""
    first, second = readme_commands()[:2]
    assert first[0] == second[0] == "experiments.train"
    assert first[first.index("--preset") + 1] == "tiny" and second[second.index("--preset") + 1] == "quick"
    snippet = next(body for lang, body in BLOCKS if lang == "python" and "make_train" in body)
    assert "make_act(" in snippet and "evaluate_policy(" in snippet


@pytest.mark.parametrize("doc", sorted(DOCS))
def test_docs_commands_parse(doc):
    """The commands of docs/ name modules that exist, and their flags are accepted (the
    README's also run, at a tiny size, below)."""
    text = DOCS[doc]
    for module, *argv in readme_commands(text):
        parser = CLI_MODULES[module].Args if module in CLI_MODULES else BENCH_ARGS[module]()
        assert dataclasses.is_dataclass(tyro.cli(parser, args=argv)), (doc, module, argv)
    for module in set(re.findall(r"python -m ((?:experiments|benchmarks)\.\w+)", text)):
        assert importlib.util.find_spec(module) is not None, (doc, module)
    for link in re.findall(r"\]\(((?!https?:)[^)#]+)\)", text):  # relative links lead somewhere
        assert (REPO / "docs" / link).exists(), (doc, link)


def tiny_argv(module: str, argv: list[str], folder: Path) -> list[str]:
    """The same command at a tiny size: preset tiny, run folders under `folder`."""
    out, flag = [], None
    for word in argv:
        if flag == "--preset":
            word = "tiny"
        elif flag in ("--out", "--run"):
            word = str(folder / word)
        out.append(word)
        flag = word if word.startswith("--") else None
    if "progress" in {f.name for f in dataclasses.fields(CLI_MODULES[module].Args)}:
        out.append("--no-progress")
    return out


@pytest.mark.slow
@pytest.mark.timeout(600)
@pytest.mark.parametrize("source", ["README.md", "docs/usage.md"])
def test_readme_commands_run_at_a_tiny_size(tmp_path, capsys, source):
    """The commands of the README and of docs/usage.md (its command line), each page's in
    order in a folder of its own, at a tiny size."""
    commands = readme_commands((REPO / source).read_text())
    assert any(module in CLI_MODULES for module, *_ in commands), source
    for module, *argv in commands:
        if module not in CLI_MODULES:  # benchmarks: parsed above, run by their own tests
            continue
        args = tyro.cli(CLI_MODULES[module].Args, args=tiny_argv(module, argv, tmp_path))
        CLI_MODULES[module].main(args)
    # What each command promises to write.
    runs_written = [p for p in (tmp_path / "runs").iterdir() if rundir.is_run(p)]
    assert runs_written
    for run in runs_written:
        assert (run / "results_test.md").exists() and (run / "learning_curve.png").exists()
    sweeps = [p for p in (tmp_path / "runs").iterdir() if (p / "sweep.json").exists()]
    for folder in sweeps:
        assert (folder / "table1.md").exists() and (folder / "learning_curves.png").exists()
        rows = list(csv_rows(folder / "table1.csv"))
        assert [r["method"] for r in rows] == list(json.loads((folder / "sweep.json").read_text())["methods"])


@pytest.mark.slow
def test_readme_python_blocks_run_at_a_tiny_size():
    """The Python examples of the README and of docs/usage.md (where its environment block
    went), executed with smaller sizes substituted (bathrooms only, 2 lanes, 1 update, a small
    network): the API calls are the documented ones."""
    python_blocks = [body for lang, body in BLOCKS + USAGE_BLOCKS if lang == "python"]
    assert len(python_blocks) >= 2
    assert any("make_train" in body for lang, body in BLOCKS if lang == "python")  # the README's library snippet
    assert any("envs.make" in body for lang, body in USAGE_BLOCKS if lang == "python")  # usage.md's environment
    small = (
        'num_lanes=2, num_updates=1, room_types=("bathroom",), hidden_size=16, attention_size=16, '
        "value_hidden=16, imagination_layer_sizes=(16, 8, 4, 8, 16, 16)"
    )
    for body in python_blocks:
        code = body.replace('split="train")', 'split="train", room_types=("bathroom",))')
        code = re.sub(r"num_lanes=\d+, num_updates=\d+", small, code)
        assert code != body, "nothing to shrink in this README block: update the substitutions"
        namespace: dict = {}
        exec(compile(code, "README.md", "exec"), namespace)  # noqa: S102
        if "make_train" in body:
            state, metrics = namespace["state"], namespace["metrics"]
            seeds = int(re.search(r"PRNGKey\(0\), (\d+)\)", body).group(1))
            assert np.asarray(state.update).tolist() == [1] * seeds
            assert np.isfinite(np.asarray(metrics["losses/total_loss"])).all()
        if "envs.make" in body:
            assert "obs" in namespace and "state" in namespace
        if "make_act" in body:  # seed 0's policy, its parameters those of seed 0's state
            H.assert_trees_bitwise_equal(namespace["act"].params.params, jax.tree.map(lambda x: x[0], state.params))


def _extending_blocks(evaluating: bool) -> list[str]:
    """docs/extending.md's Python blocks: those that evaluate a policy (tens of seconds of
    compiling) or the others."""
    blocks = re.findall(r"```python\n(.*?)```", DOCS["extending.md"], flags=re.S)
    return [b for b in blocks if ("evaluate_policy" in b) == evaluating]


def test_extending_blocks_run():
    """docs/extending.md's Python blocks run as written (they are small by design)."""
    blocks = _extending_blocks(evaluating=False)
    assert len(blocks) >= 2
    for body in blocks:
        exec(compile(body, "docs/extending.md", "exec"), {})  # noqa: S102
    from foresit_jax import methods

    assert "myint" not in methods.IMAGINATION_VARIANTS  # the example cleans up after itself


@pytest.mark.slow
def test_extending_blocks_that_evaluate_run():
    """docs/extending.md's block that acts and evaluates from a user's own code runs as written."""
    blocks = _extending_blocks(evaluating=True)
    assert len(blocks) == 1
    exec(compile(blocks[0], "docs/extending.md", "exec"), {})  # noqa: S102


def test_console_scripts_are_the_module_programs(monkeypatch, capsys):
    """Each console script of pyproject.toml names a function that runs its module's CLI
    (`foresit-train --help` prints train's usage)."""
    import tomllib

    scripts = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["scripts"]
    assert set(scripts) == {
        "foresit-train",
        "foresit-evaluate",
        "foresit-sweep",
        "foresit-tune",
        "foresit-paper",
        "foresit-probe",
        "foresit-failures",
        "foresit-compare",
    }
    for name, target in scripts.items():
        module, function = target.split(":")
        assert module == f"experiments.{name.removeprefix('foresit-')}"
        monkeypatch.setattr(sys, "argv", [name, "--help"])
        monkeypatch.setenv("XLA_FLAGS", os.environ.get("XLA_FLAGS", ""))  # restored after (sweep sets it)
        with pytest.raises(SystemExit) as exc:
            getattr(importlib.import_module(module), function)()
        assert exc.value.code == 0
        # as tyro prints it (tyro 0.9 wraps the description at the terminal's width)
        first_line = importlib.import_module(module).Args.__doc__.split("\n")[0]
        assert " ".join(first_line.split()) in " ".join(capsys.readouterr().out.split())
