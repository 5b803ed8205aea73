"""Every check before anything is written, and typed configs (issue 80, items 2 and 3).

Item 3: a `Config` field takes a value of its own type (`Config.__post_init__`,
`config.check_type`, from the dataclass's field types): a string for a bool, a tuple or a
number is refused in one line; an int for a float, a list for a tuple and numpy scalars are
taken, as plain Python values. `num_actions` and `imagination_layer_sizes` are checked
against what the agent supports, and a room type's name alone reads as that one room type
in `envs.make`, `Config` and `evaluate_policy` alike. Every run.json config kept in
docs/data still loads.

Item 2: see the tests below the line "every check before anything is written".
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from foresit_jax.config import ACTIONS, Config, field_types
from study_data import ARCHIVES, read_archive_json


# ---------------------------------------------------------------------- typed configs
@pytest.mark.parametrize(
    "fields, message",
    [
        (dict(method="a3c", priors="False"), "priors must be a bool, got 'False' (str)"),
        (dict(priors=0), "priors must be a bool, got 0 (int)"),
        (dict(maml_first_order="true"), "maml_first_order must be a bool, got 'true' (str)"),
        (dict(learning_rate="1e-3"), "learning_rate must be a float, got '1e-3' (str)"),
        (dict(gamma="0.9"), "gamma must be a float, got '0.9' (str)"),
        (dict(progress_reward=True), "progress_reward must be a float, got True (bool)"),
        (dict(perception_range="4"), "perception_range must be a float or None, got '4' (str)"),
        (dict(num_lanes="16"), "num_lanes must be an int, got '16' (str)"),
        (dict(num_lanes=16.0), "num_lanes must be an int, got 16.0 (float)"),
        (dict(method=3), "method must be a str, got 3 (int)"),
        (dict(imagination_layer_sizes="32,512"), "imagination_layer_sizes must be a tuple of ints, got '32,512' (str)"),
        (dict(imagination_layer_sizes=(32, "512")), "imagination_layer_sizes must be a tuple of ints"),
        (dict(imagination_layer_sizes=(32.0, 512)), "imagination_layer_sizes must be a tuple of ints"),
        (dict(room_types=("bathroom", 1)), "room_types must be a tuple of strs"),
    ],
)
def test_a_value_of_another_type_is_refused_naming_the_field_and_type(fields, message):
    with pytest.raises(ValueError) as e:
        Config(**fields)
    assert str(e.value).startswith(message) and "\n" not in str(e.value), str(e.value)


def test_ints_for_floats_lists_for_tuples_and_numpy_scalars_are_taken_as_plain_values():
    config = Config(
        method="a3c",
        learning_rate=np.float32(1e-3),
        num_lanes=np.int64(5),
        priors=np.bool_(True),
        gamma=1,
        perception_range=np.int32(4),
        imagination_layer_sizes=[np.int64(32), 16, 512],
        room_types=["bathroom", np.str_("kitchen")],
    )
    assert type(config.learning_rate) is float and config.learning_rate == pytest.approx(1e-3)
    assert type(config.num_lanes) is int and config.num_lanes == 5
    assert config.priors is True and config.gamma == 1 and type(config.perception_range) is int
    assert config.imagination_layer_sizes == (32, 16, 512) and type(config.imagination_layer_sizes[0]) is int
    assert config.room_types == ("bathroom", "kitchen") and type(config.room_types[1]) is str
    hash(config)  # a jit static argument
    json.dumps(dataclasses.asdict(config))  # run.json
    assert Config(imagination_layer_sizes=np.array([32, 512]), hidden_size=512).imagination_layer_sizes == (32, 512)
    assert dataclasses.replace(config, learning_rate=np.float64(3e-4)).learning_rate == 3e-4


def test_every_field_has_a_type_the_check_knows():
    """The check is made from the dataclass's types: a field of a new type must be taught to it."""
    kinds = {str(t) for t in field_types().values()}
    assert kinds <= {
        "<class 'str'>",
        "<class 'bool'>",
        "<class 'int'>",
        "<class 'float'>",
        "typing.Optional[float]",
        "tuple[str, ...]",
        "tuple[int, ...]",
    }, kinds


def test_num_actions_is_the_environments():
    from envs import catalog

    assert ACTIONS == catalog.ACTIONS and Config().num_actions == catalog.NUM_ACTIONS
    for n in (3, 5, 7):
        with pytest.raises(ValueError, match=f"num_actions must be 6, the environment's actions .*got {n}"):
            Config(num_actions=n)


def test_imagination_layer_sizes_any_number_of_layers_the_last_a_state():
    """f_w (`networks.ImaginationNet`) is one tanh layer per width, any number of them; its
    output is an imagined state, of hidden_size units."""
    assert Config(hidden_size=32, imagination_layer_sizes=(32,)).imagination_layer_sizes == (32,)
    assert len(Config(hidden_size=32, imagination_layer_sizes=(8,) * 9 + (32,)).imagination_layer_sizes) == 10
    with pytest.raises(ValueError, match="must give at least one width: f_w is one tanh layer per width"):
        Config(imagination_layer_sizes=())
    with pytest.raises(ValueError, match="must be positive ints"):
        Config(hidden_size=32, imagination_layer_sizes=(0, 32))
    with pytest.raises(ValueError, match=r"imagination_layer_sizes\[-1\] \(64\) must equal hidden_size \(32\)"):
        Config(hidden_size=32, imagination_layer_sizes=(32, 64))


def test_a_room_types_name_alone_is_that_room_type_in_config_envs_and_evaluate():
    import jax

    import envs
    from envs.gridnav import room_names

    assert Config(room_types="bathroom").room_types == ("bathroom",)
    _, params = envs.make(room_types="bathroom")
    _, one = envs.make(room_types=("bathroom",))
    assert all(jax.tree.leaves(jax.tree.map(np.array_equal, params, one)))
    # evaluate_policy and Evaluator.evaluate read `room_types` through room_names
    assert room_names("bathroom") == ("bathroom",) == room_names(("bathroom",))
    assert room_names(None) == room_names(()) == ("kitchen", "living_room", "bedroom", "bathroom")
    for bad in ("bath", ("bathroom", "bathroom")):
        with pytest.raises(ValueError, match="room type"):
            room_names(bad)


def test_evaluate_policy_takes_a_room_types_name_alone(monkeypatch):
    """evaluate_policy plays the rooms `room_names` gives (a name alone: that room), not its letters."""
    from foresit_jax import evaluate

    played = []
    monkeypatch.setattr(evaluate.Evaluator, "_per_room", lambda self, rooms, *a, **k: played.append(rooms))
    config = Config(method="a3c", hidden_size=32, attention_size=32, value_hidden=32, imagination_layer_sizes=(32,))
    policy = lambda params, carry, obs, first, key: (obs, carry)  # noqa: E731 (never called here)
    evaluate.evaluate_policy(policy, None, lambda n: (), config, "val", episodes_per_room=1, room_types="bathroom")
    evaluate.evaluate_policy(policy, None, lambda n: (), dataclasses.replace(config, room_types="kitchen"), "val", 1)
    assert played == [("bathroom",), ("kitchen",)]


@pytest.fixture(scope="module")
def archived_configs() -> dict[str, dict]:
    return {
        f"{archive}:{name}": info["config"]
        for archive in ARCHIVES
        for name, info in read_archive_json(archive).items()
        if name.endswith("/run.json")
    }


def test_every_archived_runs_config_still_loads(archived_configs):
    """Each run.json's config in docs/data rebuilds as its loaders rebuild it
    (`experiments.running.run.read`, `models.read_trained`, `experiments.evaluate`:
    `Config(**info["config"])`), to the values it records (a field added since takes its default)."""
    assert len(archived_configs) >= 32
    for name, recorded in archived_configs.items():
        try:
            config = Config(**recorded)
        except (TypeError, ValueError) as e:
            pytest.fail(f"{name}: {e}")
        rebuilt = json.loads(json.dumps(dataclasses.asdict(config)))
        assert {k: rebuilt[k] for k in recorded} == recorded, name
