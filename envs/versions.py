"""The one version pairing pip cannot express: flax 0.12.0-0.12.6 fail on jax 0.11 and newer
(at first use: `jax.core.get_opaque_trace_state` is gone), and flax 0.12.7, the first that
runs there, needs jax >= 0.10, so the package's ranges cannot raise flax's floor without
dropping jax 0.7.2 (constraints.txt). `import envs` checks the pair and stops with one line
that names the upgrade."""

from __future__ import annotations

import importlib.metadata
import re


def installed_version(package: str) -> tuple[int, ...] | None:
    """(major, minor, patch) of an installed distribution, or None when it has no metadata."""
    try:
        text = importlib.metadata.version(package)
    except importlib.metadata.PackageNotFoundError:
        return None
    return tuple(int(part) for part in re.findall(r"\d+", text)[:3])


def incompatible_pair(jax_version: tuple[int, ...] | None, flax_version: tuple[int, ...] | None) -> str | None:
    """The one-line reason a jax and flax pair cannot run together, or None when it can."""
    if jax_version is None or flax_version is None:
        return None
    if jax_version >= (0, 11) and flax_version < (0, 12, 7):
        jax_text, flax_text = ".".join(map(str, jax_version)), ".".join(map(str, flax_version))
        return (
            f"flax {flax_text} does not run on jax {jax_text} (jax.core.get_opaque_trace_state is gone "
            f"since jax 0.11): pip install 'flax>=0.12.7' (or pin jax below 0.11)"
        )
    return None


def check_jax_flax() -> None:
    """Raise ImportError naming the upgrade when the installed jax and flax cannot pair."""
    reason = incompatible_pair(installed_version("jax"), installed_version("flax"))
    if reason is not None:
        raise ImportError(reason)
