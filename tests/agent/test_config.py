"""foresit_jax.config: defaults, validation, and the methods it accepts."""

import dataclasses

import pytest

from foresit_jax.config import Config
from foresit_jax.methods import IMAGINATION_VARIANTS, ImaginationVariant


def test_paper_defaults():
    c = Config()
    assert (c.gamma, c.gae_lambda, c.entropy_coef, c.value_coef) == (0.99, 1.0, 0.01, 0.5)
    assert (c.learning_rate, c.hidden_size, c.buffer_size) == (1e-4, 512, 32)
    assert (c.sigma2_max, c.success_window, c.rnd_variance) == (0.9, 100, 0.5)
    assert len(c.imagination_layer_sizes) == 6 and min(c.imagination_layer_sizes) == 64
    assert c.frames_per_update == c.num_lanes * c.num_steps
    assert (c.rollout, c.gradient) == ("packed", "replay")


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
        ("rollout", "async", "rollout"),
        ("gradient", "finite_differences", "gradient"),
        ("value_head", "deep", "value_head must be one of \\('mlp', 'linear'\\)"),
        ("imagination_batch", 3, "imagination_batch \\(3\\) must divide buffer_size \\(32\\)"),
        ("imagination_batch", 0, "imagination_batch must be >= 1"),
        ("imagination_noise", "inside", "imagination_noise must be one of \\('output', 'input'\\)"),
    ],
)
def test_invalid_values_raise(field, value, match):
    with pytest.raises(ValueError, match=match):
        Config(**{field: value})


def test_replace_revalidates():
    with pytest.raises(ValueError, match="num_lanes"):
        dataclasses.replace(Config(), num_lanes=0)


def test_unknown_methods_and_impossible_combinations():
    with pytest.raises(ValueError, match="imagination \\['none', 'foresit'"):  # lists valid pieces
        Config(method="a3c+magic")
    for name in ("a3c+maml", "a3c+maml+foresit"):  # maml needs whole episodes, through the rollout
        with pytest.raises(ValueError, match="supports rollout \\('episodes',\\)"):
            Config(method=name)
        Config(method=name, rollout="episodes", gradient="through_rollout")
    for name in ("a3c+org", "a3c+org+foresit"):
        with pytest.raises(ValueError, match="needs setup 'org'"):
            Config(method=name, setup="savn")


def changed_fields(a: ImaginationVariant, b: ImaginationVariant):
    fields = [
        f for f in dataclasses.fields(ImaginationVariant) if f.init
    ]  # the choices, not the flags derived from them
    return {f.name for f in fields if getattr(a, f.name) != getattr(b, f.name)} - {"name"}


def test_method_pieces():
    a3c, foresit = (Config(method=m).pieces.imagination_variant for m in ("a3c", "a3c+foresit"))
    assert not a3c.uses_imagination and not Config(method="a3c").pieces.attention_critic
    assert foresit.trains_imagination and Config(method="a3c+foresit").pieces.attention_critic
    assert foresit.subgoal_mode == "argmax" and not foresit.renew_every_k
    # Each ablation is ForeSIT with exactly one change.
    assert changed_fields(IMAGINATION_VARIANTS["rnd"], foresit) == {"source"}
    assert IMAGINATION_VARIANTS["rnd"].uses_imagination and not IMAGINATION_VARIANTS["rnd"].trains_imagination
    assert changed_fields(IMAGINATION_VARIANTS["att"], foresit) == {"subgoal_mode"}
    assert IMAGINATION_VARIANTS["att"].subgoal_mode == "attention_average"
    assert changed_fields(IMAGINATION_VARIANTS["int"], foresit) == {"renew_every_k"}
    assert Config(method="int").pieces.imagination_variant.renew_every_k
