"""envs.versions: the jax/flax pair pip cannot express is refused in one line."""

from pathlib import Path

import pytest

from envs import versions

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(
    "jax_version, flax_version, refused",
    [
        ((0, 7, 2), (0, 12, 0), False),  # constraints.txt
        ((0, 10, 2), (0, 12, 6), False),  # before jax 0.11 any flax 0.12 runs
        ((0, 11, 0), (0, 12, 6), True),  # get_opaque_trace_state is gone
        ((0, 12, 0), (0, 12, 0), True),
        ((0, 11, 2), (0, 12, 7), False),  # the first flax that runs there
        ((0, 12, 0), (0, 12, 12), False),  # constraints-latest.txt
    ],
)
def test_incompatible_pair(jax_version, flax_version, refused):
    reason = versions.incompatible_pair(jax_version, flax_version)
    assert (reason is not None) == refused
    if refused:
        assert "pip install 'flax>=0.12.7'" in reason and "\n" not in reason


def test_the_installed_pair_imports_and_a_bad_one_is_an_import_error(monkeypatch):
    versions.check_jax_flax()  # the stack the suite runs on
    monkeypatch.setattr(versions, "installed_version", lambda package: {"jax": (0, 12, 0), "flax": (0, 12, 3)}[package])
    with pytest.raises(ImportError, match=r"flax 0\.12\.3 does not run on jax 0\.12\.0"):
        versions.check_jax_flax()


def test_constraints_txt_pins_every_package_the_dev_install_brings():
    """A full freeze: every distribution that `pip install -e ".[dev]"` brings in (followed
    through the installed packages' requirements, markers evaluated here) has a pin in
    constraints.txt, so CI installs exactly what the README's figures were measured with."""
    from importlib import metadata

    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name

    def pinned(name):
        lines = (REPO / name).read_text().splitlines()
        return {
            canonicalize_name(l.split("==")[0]): l.split("==")[1].strip() for l in lines if l and not l.startswith("#")
        }

    # Only where constraints.txt's stack is installed (Python 3.11; constraints-latest.txt, the
    # newest stack's, is a freeze of its own venv already).
    pins = pinned("constraints.txt")
    differ = [n for n in ("jax", "flax", "numpy", "scipy", "tyro", "matplotlib") if pins.get(n) != metadata.version(n)]
    if differ:  # the newest stack, or CI's lowest-direct leg
        pytest.skip(f"{', '.join(f'{n} {metadata.version(n)}' for n in differ)}: not constraints.txt's stack")
    seen, todo, unpinned = set(), [("foresit_jax", ("dev",))], []
    while todo:
        name, extras = todo.pop()
        try:
            dist = metadata.distribution(name)
        except metadata.PackageNotFoundError:
            continue  # not installed here (an optional dependency of a dependency)
        for text in dist.requires or ():
            req = Requirement(text)
            if req.marker is not None and not any(req.marker.evaluate({"extra": e}) for e in (*extras, "")):
                continue
            key = canonicalize_name(req.name)
            if key == "foresit-jax":
                todo.append((req.name, tuple(req.extras)))
                continue
            if key not in pins and key not in unpinned:
                unpinned.append(key)
            if (key, tuple(sorted(req.extras))) not in seen:
                seen.add((key, tuple(sorted(req.extras))))
                todo.append((req.name, tuple(req.extras)))
    assert not unpinned, f"constraints.txt lacks pins for {unpinned}: refreeze it (its header says how)"
