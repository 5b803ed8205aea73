"""A local `envs` package (or PyPI's `envs`) that shadows GridNav's makes `import
foresit_jax` fail in one line that says what shadows it and how to fix it."""

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_a_shadowing_envs_fails_in_one_line_naming_it(tmp_path):
    (tmp_path / "envs").mkdir()
    (tmp_path / "envs" / "__init__.py").write_text("# somebody else's environments\n")
    out = subprocess.run(
        [sys.executable, "-c", "import foresit_jax"], cwd=tmp_path, capture_output=True, text=True, timeout=120
    )
    assert out.returncode != 0
    last = out.stderr.strip().splitlines()[-1]
    assert last.startswith("ImportError: foresit_jax needs GridNav's `envs` package"), last
    assert str(tmp_path / "envs") in last and "pip uninstall envs" in last


def test_gridnavs_own_envs_passes_the_check():
    out = subprocess.run(
        [sys.executable, "-c", "import foresit_jax, envs; print(envs.GridNav.__name__)"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0 and out.stdout.strip() == "GridNav", out.stderr[-500:]
