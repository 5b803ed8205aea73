"""foresit_jax.config: defaults, validation and the method registry."""

import dataclasses

import pytest

from foresit_jax.config import METHODS, PLANNED_METHODS, Config, MethodFlags, method_flags


def test_paper_defaults():
    c = Config()
    assert (c.gamma, c.gae_lambda, c.entropy_coef, c.value_coef) == (0.99, 1.0, 0.01, 0.5)
    assert (c.learning_rate, c.hidden_size, c.buffer_size) == (1e-4, 512, 32)
    assert (c.sigma2_max, c.success_window, c.rnd_variance) == (0.9, 100, 0.5)
    assert len(c.imagination_layer_sizes) == 6 and min(c.imagination_layer_sizes) == 64
    assert c.num_episodes == c.num_lanes * c.num_updates


def test_frozen_and_hashable():
    c = Config()
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.num_lanes = 3
    c2 = Config(imagination_layer_sizes=[32, 8, 512])
    assert c2.imagination_layer_sizes == (32, 8, 512)
    hash(c2)


@pytest.mark.parametrize(
    "field, value, match",
    [
        ("num_lanes", 0, "num_lanes"),
        ("num_updates", 5e5, "num_updates must be an int"),
        ("buffer_size", 0, "buffer_size"),
        ("imagination_epochs", -1, "imagination_epochs"),
        ("learning_rate", -1e-4, "learning_rate"),
        ("imagination_lr", 0.0, "imagination_lr"),
        ("gamma", 1.5, "gamma"),
        ("gae_lambda", -0.1, "gae_lambda"),
        ("entropy_coef", -0.01, "entropy_coef"),
        ("sigma2_max", -1.0, "sigma2_max"),
        ("setup", "thor", "setup"),
        ("imagination_optimizer", "rmsprop", "imagination_optimizer"),
        ("imagination_layer_sizes", (512, 64, 256), "hidden_size"),
        ("num_steps", True, "num_steps"),
    ],
)
def test_invalid_values_raise(field, value, match):
    with pytest.raises(ValueError, match=match):
        Config(**{field: value})


def test_replace_revalidates():
    with pytest.raises(ValueError, match="num_lanes"):
        dataclasses.replace(Config(), num_lanes=0)


def test_unknown_and_planned_methods():
    with pytest.raises(ValueError, match="a3c\\+foresit"):  # lists valid names
        Config(method="a3c+magic")
    for name in PLANNED_METHODS:
        with pytest.raises(NotImplementedError, match="not implemented"):
            method_flags(name)
    assert set(PLANNED_METHODS) == {"a3c+maml", "a3c+maml+foresit", "a3c+org", "a3c+org+foresit"}


def changed_fields(a: MethodFlags, b: MethodFlags):
    return {f.name for f in dataclasses.fields(MethodFlags) if getattr(a, f.name) != getattr(b, f.name)}


def test_method_flags():
    a3c, foresit = METHODS["a3c"], METHODS["a3c+foresit"]
    assert not a3c.uses_imagination and not a3c.attention_critic
    assert foresit.trains_imagination and foresit.attention_critic
    assert foresit.subgoal_mode == "argmax" and not foresit.reimagine_every_k
    # Each ablation is ForeSIT with exactly one change.
    assert changed_fields(METHODS["rnd"], foresit) == {"imagination"}
    assert METHODS["rnd"].uses_imagination and not METHODS["rnd"].trains_imagination
    assert changed_fields(METHODS["att"], foresit) == {"subgoal_mode"}
    assert METHODS["att"].subgoal_mode == "attention_average"
    assert changed_fields(METHODS["int"], foresit) == {"reimagine_every_k"}
    assert Config(method="int").flags.reimagine_every_k
