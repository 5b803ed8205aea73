"""Issue 80, item 5: a first run a newcomer reads. The tiny run says it is a smoke check and
what to run for a result; progress is plain lines when stderr is not a terminal (no tqdm
`\\r` frames in a log); SR is in percent in the progress line as everywhere; each program's
`--help` shows `python -m experiments.<name>`, the choices of --preset, --setup and --method
and each preset's values; the gymnax face takes gymnax 1.x's `get_obs(state, params, key)`
and its docstring no longer speaks of a warning; docs/usage.md gives the `step_api` recipe
for gymnax's own wrappers; the README says how long its library snippet takes."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from envs import gymnax_compat
from experiments import errors
from experiments import train as train_cli
from experiments.running import presets, progress
from foresit_jax.methods import IMPLEMENTED_METHODS

ROOT = Path(__file__).resolve().parents[2]
GYMNAX = gymnax_compat.installed_gymnax_version()


# ---------------------------------------------------------------------- the smoke check
def test_the_tiny_preset_is_called_a_smoke_check_and_points_to_quick():
    config, schedule = presets.preset("tiny", "a3c+foresit")
    note = presets.smoke_note("tiny", schedule, config)
    assert note.startswith("this is a smoke check (preset tiny: 4 updates, 2 test episodes per room type)"), note
    assert "for a result run --preset quick" in note
    for name in ("quick", "house", "paper"):
        assert presets.smoke_note(name, *reversed(presets.preset(name, "a3c"))) is None


# ---------------------------------------------------------------------- progress
def test_off_a_terminal_the_progress_is_plain_lines_not_tqdm_frames(capsys):
    """stderr captured (not a terminal): `enabled=True` gives what --no-progress gives, one
    line per chunk and no carriage return; `tty=True` keeps the bar."""
    advance = progress.progress_bar(total=4, initial=0, enabled=True)
    assert not advance.enabled
    advance(2, {"method": "a3c", "SR": "12.5%"})
    advance(2, {"method": "a3c", "SR": "25.0%"})
    advance(0, None)
    err = capsys.readouterr().err
    assert "\r" not in err, repr(err)
    lines = err.splitlines()
    assert len(lines) == 2 and lines[1].endswith("4/4 updates, 0.0 min: method a3c, SR 25.0%"), lines
    assert progress.progress_bar(total=4, initial=0, enabled=True, tty=True).enabled


def test_is_terminal_of_a_stream_without_isatty_is_false():
    assert progress.is_terminal(object()) is False


def test_the_progress_line_gives_sr_in_percent():
    """`Run.train`'s postfix: the training SR as '12.5%' (it was the fraction 0.125)."""
    source = (ROOT / "experiments" / "running" / "run.py").read_text()
    assert '"SR": f"{100 * metrics[\'charts/success_rate\'].mean():.1f}%"' in source


# ---------------------------------------------------------------------- --help
PROGRAMS = ("train", "sweep", "tune", "paper", "evaluate", "compare", "probe", "failures", "foresight")


@pytest.mark.parametrize("program", PROGRAMS)
def test_help_shows_python_m_as_the_usage_line(program, capsys):
    module = __import__(f"experiments.{program}", fromlist=["Args"])
    assert errors.program_name(module.Args) == f"python -m experiments.{program}"
    with pytest.raises(SystemExit) as exit_:
        errors.run_cli(module.Args, lambda args: None, ["--help"])
    assert exit_.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: python -m experiments.{program} "), out[:200]


def _help(module, capsys) -> str:
    with pytest.raises(SystemExit):
        errors.run_cli(module.Args, lambda args: None, ["--help"])
    return " ".join(re.sub(r"[│╭╮╰╯─]", " ", capsys.readouterr().out).split())


def test_help_shows_the_choices_and_each_presets_values(capsys):
    text = _help(train_cli, capsys)
    assert "--preset {tiny,quick,house,paper}" in text
    assert "--setup {savn,org}" in text
    assert "--method METHOD[@FIELD=VALUE,...]" in text
    for method in IMPLEMENTED_METHODS:
        assert f" {method}," in text or f" {method};" in text, method
    for name in presets.PRESETS:  # each preset's values, not "(default: None)"
        assert f"{name} (" in text
    assert "num_lanes=4, num_updates=4" in text and "num_updates=3000, learning_rate=0.001" in text
    assert "(default: the preset's; see --preset)" in text
    from experiments import sweep

    text = _help(sweep, capsys)
    assert "--methods METHOD[@FIELD=VALUE,...] ..." in text and "a3c+maml+foresit" in text
    assert "--preset {tiny,quick,house,paper}" in text and "--setup {savn,org}" in text


def test_an_arm_is_still_accepted_by_method_and_an_unknown_preset_is_one_line(tmp_path, capsys):
    """The choices are shown, not enforced by tyro: an arm parses, and a bad preset or setup
    is still the project's one-line refusal (not tyro's usage box)."""
    args = []
    errors.run_cli(train_cli.Args, args.append, ["--method", "a3c@learning_rate=3e-4", "--preset", "tiny"])
    assert args[0].method == "a3c@learning_rate=3e-4"
    for flag, value, says in (("--preset", "huge", "unknown preset 'huge'"), ("--setup", "thor", "setup must be")):
        with pytest.raises(SystemExit) as exit_:
            train_cli.cli(["--preset", "tiny", flag, value, "--out", str(tmp_path / "x")])
        assert exit_.value.code == 2
        err = capsys.readouterr().err
        assert err.startswith("error: ") and says in err and len(err.strip().splitlines()) == 1, err


# ---------------------------------------------------------------------- the gymnax face
def test_get_obs_takes_gymnax_1s_key_argument():
    env, params = envs.make_gymnax(room_types=("bathroom",))
    _, state = env.reset_env(jax.random.PRNGKey(0), params)
    want = env.get_obs(state, params)
    np.testing.assert_array_equal(env.get_obs(state, params, jax.random.PRNGKey(1)), want)
    np.testing.assert_array_equal(env.get_obs(state, params=params, key=jax.random.PRNGKey(2)), want)


def test_the_gymnax_docstring_speaks_of_no_warning_and_keeps_the_default():
    doc = gymnax_compat.__doc__
    assert "warns as" not in doc and "silences the warning" not in doc
    assert gymnax_compat.default_step_api() == "done"
    env, _ = envs.make_gymnax(room_types=("bathroom",))
    assert env.step_api == "done"


def test_usage_gives_the_step_api_recipe_for_gymnaxs_own_wrappers():
    text = (ROOT / "docs" / "usage.md").read_text()
    assert "from gymnax.wrappers.purerl import LogWrapper" in text
    assert 'envs.make_gymnax("GridNav-v0", step_api="terminated_truncated"' in text


@pytest.mark.slow  # compiles GridNav's reset and step under LogWrapper (~7 s on 2 cores)
@pytest.mark.skipif(GYMNAX is None or GYMNAX < (1,), reason="needs gymnax >= 1.0 (its purerl wrappers)")
def test_the_usage_recipe_for_gymnaxs_log_wrapper_runs():
    """docs/usage.md's recipe, as written: gymnax 1.x's LogWrapper over the six-value env."""
    text = (ROOT / "docs" / "usage.md").read_text()
    recipe = re.search(
        r"```python\n( *import envs, jax\n *from gymnax\.wrappers\.purerl import LogWrapper\n.*?) *```", text, re.S
    )
    assert recipe, "docs/usage.md lost the LogWrapper recipe"
    code = textwrap.dedent(recipe.group(1))
    scope: dict = {}
    exec(compile(code, "docs/usage.md", "exec"), scope)  # noqa: S102 (the docs' own snippet)
    assert scope["obs"].ndim == 1 and "returned_episode_returns" in scope["info"]
    from gymnax.wrappers.purerl import LogWrapper

    five, params = envs.make_gymnax(room_types=("bathroom",))  # the default five-value step: theirs fails
    wrapped = LogWrapper(five)
    _, state = wrapped.reset(jax.random.PRNGKey(0), params)
    with pytest.raises(ValueError, match="not enough values to unpack"):
        wrapped.step(jax.random.PRNGKey(1), state, jnp.int32(0), params)


# ---------------------------------------------------------------------- the README
def test_the_readme_says_how_long_its_snippet_takes_and_that_jit_is_asynchronous():
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## Library use") : text.index("## Related work")]
    assert "2-core" in section and re.search(r"\d+(\.\d+)? (s|min)\b", section), section
    assert "block_until_ready" in section


# ---------------------------------------------------------------------- end to end (slow)
@pytest.mark.slow  # trains the tiny preset from the command line (a minute or two on 2 cores)
def test_the_tiny_run_redirected_says_smoke_check_and_logs_plain_percent_lines(tmp_path):
    out = tmp_path / "run"
    done = subprocess.run(
        [sys.executable, "-m", "experiments.train", "--preset", "tiny", "--method", "a3c", "--out", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "this is a smoke check (preset tiny" in done.stdout and "--preset quick" in done.stdout
    assert "\r" not in done.stderr, done.stderr[-500:]
    lines = [line for line in done.stderr.splitlines() if " updates, " in line]
    assert len(lines) == 2, done.stderr[-2000:]
    assert all(re.search(r"SR \d+\.\d%, val SR \d+\.\d%", line) for line in lines), lines
