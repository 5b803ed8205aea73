"""experiments.running.presets: a preset's overrides are checked, every Config field is a flag
of train and sweep, and each flag's help is its field's docstring.  (Arm labels:
tests/experiments/test_arm_labels.py.)"""

import dataclasses
import re

import pytest
import tyro

from experiments import sweep
from experiments import train as train_cli
from experiments.running import presets
from foresit_jax.config import Config


# Cheap in-process CLI calls for every test of this module (tests/conftest.py).
pytestmark = pytest.mark.usefixtures("cheap_experiments")


def test_buffer_size_below_one_is_refused():
    """(Not a CLI flag; a preset override or a Config.)"""
    with pytest.raises(ValueError, match="buffer_size must be >= 1"):
        presets.preset("tiny", "a3c+foresit", buffer_size=0)


def test_every_config_field_is_a_flag_of_train_and_sweep():
    """Each Config field but the action count (the environment's) is a flag of train and
    of sweep: its own, or one of the unprefixed Config fields (presets.config_fields)."""
    wanted = {f.name for f in dataclasses.fields(Config)} - {"num_actions", "method"}
    for cli in (train_cli, sweep):
        own = {f.name for f in dataclasses.fields(cli.Args)}
        nested = {f.name for f in dataclasses.fields(cli.Args().config)}
        assert wanted <= own | nested and not own & nested, cli.__name__
    args = tyro.cli(
        train_cli.Args,
        args=[
            "--gamma",
            "0.9",
            "--room-types",
            "bathroom",
            "kitchen",
            "--imagination-layer-sizes",
            "8",
            "128",
            "--maml-first-order",
            "True",
        ],
    )
    config, _ = train_cli.build(args)
    assert (config.gamma, config.room_types, config.maml_first_order) == (0.9, ("bathroom", "kitchen"), True)
    assert config.entropy_coef == presets.preset("quick", "a3c+foresit")[0].entropy_coef  # the rest: the preset's


def test_each_config_field_flag_is_helped_by_its_docstring_on_one_line(capsys):
    """The help of a Config field's flag is the docstring under the field, its source line
    breaks joined (presets._field_docs, read with tyro's docstring_parser): what each
    flag's annotation carries, and what `--help` prints."""
    import typing

    docs = presets._field_docs(Config)
    assert set(docs) == {f.name for f in dataclasses.fields(Config)}
    assert docs["gamma"] == "Discount factor."
    assert all("\n" not in d and "  " not in d for d in docs.values())
    for fields in (presets.TrainConfigFields, presets.SweepConfigFields):
        for name, hint in typing.get_type_hints(fields, include_extras=True).items():
            (arg,) = [m for m in hint.__metadata__ if isinstance(m, type(tyro.conf.arg()))]
            assert arg.help == docs[name], name
    with pytest.raises(SystemExit):
        tyro.cli(train_cli.Args, args=["--help"])
    shown = " ".join(re.sub("[\u2500-\u257f]", " ", capsys.readouterr().out).split())  # box drawing out
    for name in ("priors", "rollout", "gamma", "entropy_coef"):
        assert docs[name] in shown, name
