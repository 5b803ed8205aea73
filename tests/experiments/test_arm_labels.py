"""A run is what its label says (issue 80, item 1).

An arm (`METHOD@field=value,...`, `presets.split_arm`) and a flag that give one field two
values are refused, naming both; an arm value or flag that breaks the method's requirement
(maml's whole episodes) is refused with what the method needs, one that meets it is kept;
two arms that normalise the same (`presets.normalise_arm`) are refused as duplicates, while
a run keeps its user's spelling. Every refusal comes before anything is written.

The archive audit: every sweep kept in docs/data/*.tar.xz rebuilds under these rules, each
arm's label round-trips, and each run's recorded config (run.json) has what its label, its
preset and its sweep's flags say. On a mismatch the docs are corrected, never this audit.
Only the archives' JSON files are read (no training, no compile).
"""

from __future__ import annotations

import dataclasses
import json
import re
import shlex
from pathlib import Path, PurePosixPath

import pytest

from experiments import rundir, sweep, train, tune
from experiments.running import presets
from experiments.running.presets import normalise_arm, preset, split_arm
from foresit_jax.methods import parse_method
from study_data import ARCHIVES, read_archive_json

ROOT = Path(__file__).resolve().parents[2]


def cli_error(cli, argv, capsys) -> str:
    """Run a CLI that must fail: exit status 2, one `error:` line on stderr, no traceback."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        cli([str(a) for a in argv])
    err = capsys.readouterr().err
    assert exc.value.code == 2, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in err, err
    return lines[0]


# ---------------------------------------------------------------------- an arm and a flag
def test_an_arm_and_a_flag_that_disagree_are_refused_naming_both():
    with pytest.raises(ValueError) as e:
        preset("tiny", "a3c@learning_rate=1e-3", learning_rate=3e-4)
    line = str(e.value)
    assert "\n" not in line
    assert "arm 'a3c@learning_rate=1e-3' sets learning_rate=0.001" in line and "--learning-rate gives 0.0003" in line
    with pytest.raises(ValueError, match="num_updates=3500 but --num-updates gives 9000"):
        preset("quick", "a3c@rollout=episodes,num_steps=30,num_updates=3500", num_updates=9000)
    with pytest.raises(ValueError, match="imagination_input='mlp' but --imagination-input gives 'head'"):
        preset("tiny", "a3c+foresit@imagination_input=mlp", imagination_input="head")


def test_an_arm_and_a_flag_that_agree_are_kept():
    assert preset("tiny", "a3c@learning_rate=1e-3", learning_rate=0.001)[0].learning_rate == 1e-3
    assert preset("tiny", "a3c@num_steps=20", num_steps=20)[0].num_steps == 20
    # a None override is no flag given
    assert preset("tiny", "a3c@learning_rate=1e-3", learning_rate=None)[0].learning_rate == 1e-3
    # the arm over the preset, the flag over the preset: each its own field
    config = preset("quick", "a3c@learning_rate=3e-4", gamma=0.9)[0]
    assert (config.learning_rate, config.gamma, config.num_lanes) == (3e-4, 0.9, 32)


def test_train_refuses_an_arm_and_a_flag_that_disagree_before_writing(tmp_path, capsys):
    out = tmp_path / "o"
    argv = ["--preset", "tiny", "--method", "a3c@learning_rate=1e-3", "--learning-rate", "3e-4", "--out", out]
    line = cli_error(train.cli, argv, capsys)
    assert "a3c@learning_rate=1e-3" in line and "--learning-rate gives 0.0003" in line
    assert not out.exists()


def test_sweep_refuses_an_arm_and_a_flag_that_disagree_before_writing(tmp_path, capsys):
    out = tmp_path / "s"
    argv = ["--preset", "tiny", "--methods", "a3c", "a3c@learning_rate=1e-3", "--learning-rate", "3e-4", "--out", out]
    line = cli_error(sweep.cli, argv, capsys)
    assert "a3c@learning_rate=1e-3" in line and "--learning-rate gives 0.0003" in line
    assert not out.exists()


# ---------------------------------------------------------------------- a method's requirements
def test_an_arm_or_flag_below_maml_whole_episodes_is_refused_with_the_minimum():
    for arm, flags, said in (
        ("a3c+maml@num_steps=5", {}, "arm 'a3c+maml@num_steps=5' sets num_steps=5"),
        ("a3c+maml", {"num_steps": 12}, "--num-steps 12"),
        ("a3c+maml+foresit@num_steps=29", {}, "num_steps=29"),
    ):
        with pytest.raises(ValueError) as e:
            preset("tiny", arm, **flags)
        line = str(e.value)
        assert "\n" not in line and said in line and "a3c+maml" in line and "num_steps >= 30" in line, line
        assert "rollout='packed'" not in line  # a hint the method cannot follow is not given
    with pytest.raises(ValueError, match="num_steps >= 60"):  # the house's training limit
        preset("house", "a3c+maml@num_steps=30")


def test_a_rollout_or_gradient_maml_cannot_use_is_refused():
    with pytest.raises(ValueError) as e:
        preset("tiny", "a3c+maml@rollout=packed")
    assert "arm 'a3c+maml@rollout=packed' sets rollout='packed'" in str(e.value)
    assert "a3c+maml needs whole episodes" in str(e.value)
    with pytest.raises(ValueError, match="--rollout 'packed', but a3c\\+maml needs whole episodes"):
        preset("tiny", "a3c+maml", rollout="packed")
    with pytest.raises(ValueError, match="a3c\\+maml differentiates through the rollout"):
        preset("tiny", "a3c+maml@gradient=replay")
    with pytest.raises(ValueError, match="--gradient 'replay', but a3c\\+maml differentiates"):
        preset("tiny", "a3c+maml", gradient="replay")


def test_what_meets_a_requirement_is_kept_and_the_preset_is_raised():
    assert preset("tiny", "a3c+maml@num_steps=40")[0].num_steps == 40
    assert preset("tiny", "a3c+maml", num_steps=45)[0].num_steps == 45
    config = preset("tiny", "a3c+maml@rollout=episodes,gradient=through_rollout")[0]
    assert (config.rollout, config.gradient, config.num_steps) == ("episodes", "through_rollout", 30)
    # the requirement applies over the preset's own fields: quick steps 16, maml whole episodes
    config = preset("quick", "a3c+maml")[0]
    assert (config.rollout, config.gradient, config.num_steps) == ("episodes", "through_rollout", 30)
    assert preset("house", "a3c+maml")[0].num_steps == 60


def test_whole_episodes_shorter_than_the_limit_are_refused_for_any_method():
    """Trainer.__init__ refuses these too, but after a program wrote its run.json."""
    with pytest.raises(ValueError, match="--num-steps 5, but rollout=episodes .* num_steps >= 30, or use rollout="):
        preset("tiny", "a3c", rollout="episodes", num_steps=5)
    with pytest.raises(ValueError, match="preset 'quick' steps 16 at a time: give num_steps >= 30 too"):
        preset("quick", "a3c@rollout=episodes")
    assert preset("quick", "a3c@rollout=episodes,num_steps=30")[0].num_steps == 30


@pytest.mark.parametrize(
    "argv",
    [
        ["--method", "a3c+maml", "--num-steps", "12"],
        ["--method", "a3c+maml@num_steps=5"],
        ["--method", "a3c+maml@rollout=packed"],
        ["--method", "a3c", "--rollout", "episodes", "--num-steps", "5"],
    ],
    ids=lambda a: " ".join(a),
)
def test_train_refuses_a_broken_requirement_before_writing(argv, tmp_path, capsys):
    out = tmp_path / "o"
    cli_error(train.cli, ["--preset", "tiny", "--out", out, *argv], capsys)
    assert not out.exists()
    out.mkdir()  # an empty --out given: left empty, so that the retry is not refused as "not empty"
    cli_error(train.cli, ["--preset", "tiny", "--out", out, *argv], capsys)
    assert list(out.iterdir()) == []


# ---------------------------------------------------------------------- normalising arms
def test_normalise_arm_compares_but_keeps_the_label():
    same = [
        "a3c@learning_rate=1e-3",
        "A3C@learning_rate=0.001",
        "a3c@learning_rate=1e-3,",
        " a3c @ learning_rate = 1E-3 ",
        "a3c@learning_rate=1e-3,learning_rate=0.001",  # repeated with one value
    ]
    assert {normalise_arm(a) for a in same} == {"a3c@learning_rate=0.001"}
    assert normalise_arm("maml+foresit@sigma2_max=0,num_steps=40") == "a3c+maml+foresit@num_steps=40,sigma2_max=0.0"
    assert normalise_arm("a3c+critic@attention_key_gradient=stopped") == "a3c+critic@attention_key_gradient=stopped"
    assert normalise_arm("a3c@maml_first_order=TRUE") == "a3c@maml_first_order=true"
    assert normalise_arm("a3c") == "a3c" and normalise_arm("A3C+Foresit") == "a3c+foresit"
    assert normalise_arm("a3c@learning_rate=1e-3") != normalise_arm("a3c@learning_rate=3e-4")
    # a preset keeps the arm as the user wrote it, as the Config's method its method part
    assert preset("tiny", "a3c@learning_rate=1e-3,")[0].learning_rate == 1e-3


def test_a_field_given_twice_with_two_values_is_refused():
    with pytest.raises(ValueError) as e:
        split_arm("a3c@learning_rate=1e-3,learning_rate=3e-4")
    assert "sets learning_rate twice (0.001 and 0.0003)" in str(e.value) and "\n" not in str(e.value)
    assert split_arm("a3c@learning_rate=1e-3,learning_rate=0.001") == ("a3c", {"learning_rate": 1e-3})


def test_sweep_refuses_two_spellings_of_one_arm_naming_both(tmp_path, capsys):
    out = tmp_path / "s"
    argv = ["--preset", "tiny", "--out", out, "--methods", "a3c@learning_rate=1e-3", "A3C@learning_rate=0.001,"]
    line = cli_error(sweep.cli, argv, capsys)
    assert "a3c@learning_rate=1e-3 and A3C@learning_rate=0.001," in line and "the same arm" in line
    line = cli_error(sweep.cli, ["--preset", "tiny", "--out", out, "--methods", "a3c+maml", "maml"], capsys)
    assert "a3c+maml and maml" in line
    assert "a3c more than once" in cli_error(
        sweep.cli, ["--preset", "tiny", "--out", out, "--methods", "a3c", "a3c"], capsys
    )
    assert not out.exists()


def test_tune_refuses_two_spellings_of_one_method(tmp_path, capsys):
    out = tmp_path / "t"
    line = cli_error(
        tune.cli, ["--preset", "tiny", "--out", out, "--methods", "a3c", "A3C ", "--grid", "gamma=0.9,0.99"], capsys
    )
    assert "a3c and A3C " in line and "the same arm" in line
    assert not out.exists()


# ---------------------------------------------------------------------- the archives
@pytest.fixture(scope="module")
def archives() -> dict[str, dict[str, dict]]:
    return {archive: read_archive_json(archive) for archive in ARCHIVES}


def sweep_overrides(info: dict) -> dict:
    """The Config fields a sweep's sweep.json says it set: its num_updates, setup and --config flags."""
    given = {"num_updates": info["num_updates"], "setup": info["setup"], **(info.get("config") or {})}
    return {k: v for k, v in given.items() if v is not None}


def check_round_trip(arm: str) -> None:
    """An arm parses, keeps its fields through normalising, and normalises to a fixed point."""
    method, fields = split_arm(arm)
    canonical = normalise_arm(arm)
    assert split_arm(canonical) == (parse_method(method).name, fields), arm
    assert normalise_arm(canonical) == canonical, arm


def test_every_archive_is_found():
    assert len(ARCHIVES) >= 25 and "replication_3x.tar.xz" in ARCHIVES


@pytest.mark.parametrize("archive", ARCHIVES)
def test_every_archived_arm_round_trips_and_rebuilds(archive, archives):
    """Each arm of each sweep (and tune) in the archive parses, round-trips through
    normalising, keeps its spelling as its folder name, is no duplicate of another, and
    rebuilds with its sweep's preset and flags under the rules above."""
    found = archives[archive]
    sweeps = {k: v for k, v in found.items() if k.endswith("sweep.json")}
    assert sweeps, f"{archive}: no sweep.json"
    for name, info in sweeps.items():
        assert not presets.duplicate_arms(info["methods"]), (archive, name)
        for arm in info["methods"]:
            check_round_trip(arm)
            assert rundir.arm_folder(Path("s"), arm).name == arm  # the label is the folder's name
            try:
                preset(info["preset"], arm, **sweep_overrides(info))
            except ValueError as e:
                pytest.fail(f"{archive} {name}: arm {arm!r} does not rebuild: {e}")
    for name, info in found.items():
        if name.endswith("tune.json"):
            assert not presets.duplicate_arms(info["methods"]), (archive, name)
            for arm in info["methods"]:
                check_round_trip(arm)


def the_label_says(run: dict, sweep_info: dict) -> dict:
    """What a run's label, preset and sweep say of its Config: the preset's fields, the
    method's requirements, the sweep's flags, the arm's fields (defaults are not said)."""
    method, fields = split_arm(run["arm"])
    said = {**presets.PRESETS[run["preset"]][0], **parse_method(method).required_config}
    said.update(sweep_overrides(sweep_info))
    said.update(fields)
    return rundir.jsonable(said)


def audit(found: dict[str, dict]) -> list[str]:
    """The mismatches of an archive's runs (`found`: its JSON files by member name) with
    their labels: for every run.json, every field its arm sets must have that value in the
    recorded config, and so must every field its preset, its method's requirements and its
    sweep's flags set; rebuilding the run (`preset`) under the rules above must not refuse
    it and must give the recorded value of each field its arm sets, of num_updates,
    num_steps, rollout and gradient."""
    mismatches = []
    for name, run in found.items():
        if not name.endswith("/run.json"):
            continue
        path = PurePosixPath(name)
        sweep_info = found[str(path.parent.parent.parent / "sweep.json")]
        arm, recorded = run["arm"], run["config"]
        method, fields = split_arm(arm)
        if path.parent.name != arm or arm not in sweep_info["methods"]:
            mismatches.append(
                f"{name}: labelled {arm!r}, in {path.parent.name!r} of a sweep of {sweep_info['methods']}"
            )
        if run["preset"] != sweep_info["preset"] or not run["method"] == method == recorded["method"]:
            mismatches.append(f"{name}: preset {run['preset']!r}, method {run['method']!r}, arm {arm!r}")
        for field, value in fields.items():
            if recorded.get(field) != value:
                mismatches.append(f"{name}: the arm sets {field}={value!r}, the run recorded {recorded.get(field)!r}")
        for field, value in the_label_says(run, sweep_info).items():
            if recorded.get(field) != value:
                mismatches.append(f"{name}: {field} should be {value!r}, the run recorded {recorded.get(field)!r}")
        try:
            config = rundir.jsonable(dataclasses.asdict(preset(run["preset"], arm, **sweep_overrides(sweep_info))[0]))
        except ValueError as e:
            mismatches.append(f"{name}: does not rebuild: {e}")
            continue
        for field in ("method", "num_updates", "num_steps", "rollout", "gradient", *fields):
            if config[field] != recorded[field]:
                mismatches.append(f"{name}: rebuilt {field}={config[field]!r}, the run recorded {recorded[field]!r}")
    return mismatches


@pytest.mark.parametrize("archive", ARCHIVES)
def test_the_archive_audit_each_run_is_what_its_label_says(archive, archives):
    mismatches = audit(archives[archive])
    assert not mismatches, "\n".join(mismatches)


def test_the_audit_reads_the_runs_it_should(archives):
    """The archives that keep run.json (those since the run format) are audited run by run."""
    runs = {a: sum(k.endswith("/run.json") for k in found) for a, found in archives.items()}
    assert runs["replication_3x.tar.xz"] == 3 and runs["channels_stage2.tar.xz"] == 5
    assert sum(runs.values()) >= 32


def test_the_audit_catches_a_run_that_is_not_what_its_label_says(archives):
    """The audit's own check: a run.json whose recorded values are not its label's fails it."""
    found = json.loads(json.dumps(archives["replication_3x.tar.xz"]))
    assert audit(found) == []
    name = "replication_3x/methods/a3c@learning_rate=1e-3/run.json"
    found[name]["config"]["learning_rate"] = 3e-4  # a flag that won over the arm
    found[name]["config"]["num_lanes"] = 16  # a flag not recorded in sweep.json
    said = audit(found)
    assert f"{name}: the arm sets learning_rate=0.001, the run recorded 0.0003" in said
    assert f"{name}: num_lanes should be 32, the run recorded 16" in said


# ---------------------------------------------------------------------- the docs' arms
ARM_FLAGS = ("--methods", "--arms", "--pairs")


def shell_commands(text: str):
    """The commands of a Markdown file's code blocks (fenced, or indented by four spaces),
    continuation lines joined, with the block's `NAME=value` assignments substituted for `$NAME`."""
    indented = re.findall(r"(?m)((?:^ {4}.*\n)+)", re.sub(r"```.*?```", "", text, flags=re.S))
    for block in [*re.findall(r"```[a-z]*\n(.*?)```", text, flags=re.S), *indented]:
        names = {}
        for line in block.replace("\\\n", " ").splitlines():
            try:
                tokens = shlex.split(line, comments=True)
            except ValueError:
                continue
            if len(tokens) == 1 and re.fullmatch(r"[A-Z_]+=.*", tokens[0]):
                key, _, value = tokens[0].partition("=")
                names[key] = value
                continue
            yield [re.sub(r"\$\{?([A-Z_]+)\}?", lambda m: names.get(m[1], m[0]), t) for t in tokens]


def docs_arms() -> dict[str, set[str]]:
    """{arm: the docs files that write it} for every arm given to --methods, --arms or
    --pairs (A:B) in the docs' command blocks, and every inline code span that is an arm
    with fields (`a3c@learning_rate=3e-4`, as the plans' tables write them)."""
    found = {}
    for path in sorted([*(ROOT / "docs").rglob("*.md"), ROOT / "README.md"]):
        for arm in re.findall(r"`([a-z0-9+]+@[a-z_0-9]+=[^`\s]*)`", path.read_text()):
            if "..." not in arm:
                found.setdefault(arm, set()).add(str(path.relative_to(ROOT)))
        for tokens in shell_commands(path.read_text()):
            for i, token in enumerate(tokens):
                if token not in ARM_FLAGS:
                    continue
                for value in tokens[i + 1 :]:
                    if value.startswith("-"):
                        break
                    for arm in value.split(":") if token == "--pairs" else [value]:
                        placeholder = any(x in arm for x in ("$", "<", ">", "...")) or re.search(r"=[A-Z_]+(,|$)", arm)
                        if not placeholder:  # (a value still to be chosen, W_C, is not an arm yet)
                            found.setdefault(arm, set()).add(str(path.relative_to(ROOT)))
    return found


def test_every_arm_the_docs_write_round_trips():
    arms = docs_arms()
    assert len(arms) >= 20 and "a3c@learning_rate=3e-4" in arms
    assert "a3c@rollout=episodes,num_steps=30,num_updates=3500" in arms  # through docs/mechanism.md's $W
    assert "a3c@learning_rate=3e-4,aux_target=compass,aux_weight=0.1" in arms  # a plan's table
    for arm, where in sorted(arms.items()):
        try:
            check_round_trip(arm)
        except (ValueError, AssertionError) as e:
            pytest.fail(f"{sorted(where)}: arm {arm!r} does not round-trip: {e}")
