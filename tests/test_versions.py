"""envs.versions: the jax/flax pair pip cannot express is refused in one line."""

import pytest

from envs import versions


@pytest.mark.parametrize("jax_version, flax_version, refused", [
    ((0, 7, 2), (0, 12, 0), False),   # constraints.txt
    ((0, 10, 2), (0, 12, 6), False),  # before jax 0.11 any flax 0.12 runs
    ((0, 11, 0), (0, 12, 6), True),   # get_opaque_trace_state is gone
    ((0, 12, 0), (0, 12, 0), True),
    ((0, 11, 2), (0, 12, 7), False),  # the first flax that runs there
    ((0, 12, 0), (0, 12, 12), False),  # constraints-latest.txt
])  # fmt: skip
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
