"""foresit_jax.methods: names parse into pieces; impossible combinations are clear errors;
gradient paths are declared per method and validated by Config."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

from foresit_jax.config import Config
from foresit_jax.methods import IMAGINATION_VARIANTS, IMPLEMENTED_METHODS, PAPER_METHODS, Method, parse_method
from foresit_jax.imagination import renews


@pytest.mark.parametrize(
    "name, base, encoder, imagination",
    [
        ("a3c", "a3c", "plain", "none"),
        ("a3c+foresit", "a3c", "plain", "foresit"),
        ("foresit+a3c", "a3c", "plain", "foresit"),
        ("rnd", "a3c", "plain", "rnd"),
        ("org+rnd", "a3c", "org", "rnd"),
        ("a3c+org+foresit", "a3c", "org", "foresit"),
        ("a3c+maml+foresit", "maml", "plain", "foresit"),
        ("maml", "maml", "plain", "none"),
        ("a3c+maml", "maml", "plain", "none"),
        (" A3C+Int ", "a3c", "plain", "int"),
        ("a3c+critic", "a3c", "plain", "none"),
        ("org+critic", "a3c", "org", "none"),
        ("a3c+foresit+plaincritic", "a3c", "plain", "foresit"),
    ],
)
def test_names_parse_into_pieces(name, base, encoder, imagination):
    method = parse_method(name)
    assert (method.base, method.encoder, method.imagination_variant.name) == (base, encoder, imagination)


@pytest.mark.parametrize(
    "name, critic, canonical",
    [
        ("a3c", "plain", "a3c"),
        ("a3c+critic", "attention", "a3c+critic"),
        ("a3c+foresit", "attention", "a3c+foresit"),
        ("critic+foresit", "attention", "a3c+foresit"),
        ("a3c+foresit+plaincritic", "plain", "a3c+foresit+plaincritic"),
        ("a3c+plaincritic", "plain", "a3c"),
        ("org+rnd", "attention", "a3c+org+rnd"),
        ("plaincritic+org+rnd", "plain", "a3c+org+rnd+plaincritic"),
        ("a3c+maml+critic", "attention", "a3c+maml+critic"),
        ("a3c+org+int+plaincritic", "plain", "a3c+org+int+plaincritic"),
    ],
)
def test_the_critic_is_its_own_piece(name, critic, canonical):
    """Every imagination variant of the paper defaults to the attention critic (its rows
    keep their meaning), no imagination to the plain one; either can be named."""
    method = parse_method(name)
    assert method.critic == critic and method.attention_critic == (critic == "attention")
    assert method.name == canonical and parse_method(canonical) == method


def test_att_needs_the_attention_critic():
    with pytest.raises(ValueError, match="needs the attention critic"):
        parse_method("a3c+att+plaincritic")
    with pytest.raises(ValueError, match="two critic"):
        parse_method("a3c+critic+plaincritic")


def test_canonical_names_round_trip():
    for name in IMPLEMENTED_METHODS + PAPER_METHODS:
        assert parse_method(name).name == name
    assert parse_method("rnd").name == "a3c+rnd"


@pytest.mark.parametrize(
    "name, match",
    [
        ("a3c+ppo", "unknown piece 'ppo'"),
        ("foresit+rnd", "two imagination"),
        ("maml+maml", "two base"),
        ("", "non-empty"),
    ],
)
def test_bad_names(name, match):
    with pytest.raises(ValueError, match=match):
        parse_method(name)


def test_object_graph_on_the_savn_setup_is_a_clear_error():
    with pytest.raises(ValueError, match="needs setup 'org'"):
        Config(method="a3c+org+foresit", setup="savn")
    config = Config(method="a3c+org+foresit", setup="org")
    assert config.pieces.encoder == "org" and config.pieces.greedy_evaluation  # ORG evaluates greedily
    assert not Config(method="a3c+foresit").pieces.greedy_evaluation  # SAVN samples


def test_gradient_paths_are_declared_per_method():
    assert Method(base="a3c").gradients == ("replay", "through_rollout")
    # MAML's parameters change inside an episode: the replay (one parameter set per
    # window) would be silently wrong, so only differentiating through the rollout is allowed.
    assert Method(base="maml").gradients == ("through_rollout",)
    with pytest.raises(ValueError, match="gradient"):
        Config(gradient="backprop")


def test_imagination_pieces():
    foresit, att, rnd, intv, none = (IMAGINATION_VARIANTS[n] for n in ("foresit", "att", "rnd", "int", "none"))
    assert foresit.trains_imagination and foresit.critic == "attention" and foresit.subgoal_mode == "argmax"
    assert att.trains_imagination and att.subgoal_mode == "attention_average"
    assert rnd.uses_imagination and not rnd.trains_imagination
    assert not none.uses_imagination and none.critic == "plain"
    steps = jnp.arange(25)
    np.testing.assert_array_equal(renews(foresit, steps, 10), steps == 0)
    np.testing.assert_array_equal(renews(intv, steps, 10), steps % 10 == 0)
    # the derived flags follow the source when a record is replaced
    assert dataclasses.replace(none, source="goal_view").reads_goal_view and not none.reads_goal_view
    assert dataclasses.replace(foresit, name="x") != foresit  # frozen, comparable


def test_no_code_outside_the_pieces_tests_a_base_or_encoder_name():
    """Methods compose from the pieces' behaviour (`Base`, `Encoder`, `ImaginationVariant`
    records): outside foresit_jax/methods.py no module compares a base's or an
    encoder's name."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    pattern = re.compile(r"""\.(base|encoder)\s*[!=]=|[!=]=\s*["'](maml|org|a3c|plain)["']""")
    offenders = []
    for folder in ("foresit_jax", "experiments", "examples"):  # envs knows no methods (its setups are "org" too)
        for path in sorted((root / folder).glob("*.py")):
            if path.name == "methods.py":
                continue
            for number, line in enumerate(path.read_text().splitlines(), 1):
                if pattern.search(line) and "setup" not in line:
                    offenders.append(f"{path.relative_to(root)}:{number}: {line.strip()}")
    assert not offenders, "\n".join(offenders)


@pytest.mark.slow
def test_the_trainer_and_the_evaluator_choose_the_bases_window_once(monkeypatch):
    """The a3c base's window is `rollout.act_window`, run once per window (wrapped to count
    its calls; traced only); the maml base's is `maml.act`, which hands `maml.adaptive_act`
    (a stand-in that records its call) Eq. 7's variance and runs no window beside it. The
    Trainer and the Evaluator (`base_acting`) choose the same one."""
    import jax

    import train_helpers as H
    from foresit_jax import maml, rollout
    from foresit_jax.evaluate import base_acting
    from foresit_jax.rollout import ActOptions, AgentParams, BoundEnv
    from foresit_jax.train import Trainer

    env, env_params = H.bathroom_env()
    env = BoundEnv(env, env_params)
    obs, _ = env.env.reset(jax.random.key(0), env_params)
    calls, real_window = [], rollout.act_window

    def counting(*args, **kwargs):
        calls.append(args[6])  # the ActOptions
        return real_window(*args, **kwargs)

    monkeypatch.setattr(rollout, "act_window", counting)

    def acting_of(config):
        trainer = Trainer(config)
        nets = trainer.networks
        params, w_params = nets.init(jax.random.key(1), obs)
        assert base_acting(config).act is trainer.act_window
        return trainer, AgentParams(params, w_params), rollout.start(nets, jax.random.key(2), env, 2)

    trainer, acting, actor = acting_of(H.tiny_config("a3c", num_lanes=2, num_steps=3, rollout="packed"))
    assert trainer.act_window is counting
    traj = jax.eval_shape(lambda a: trainer.act(a, env, actor, jax.random.key(3))[1], acting)
    assert len(calls) == 1 and calls[0].record_inputs is True and traj.actions.shape == (3, 2)

    adaptive = []

    def stand_in(*args):
        adaptive.append(args)
        return args[3], "traj", "end", []  # (actor, Trajectory, WindowEnd, thetas): nothing is run

    monkeypatch.setattr(maml, "adaptive_act", stand_in)
    trainer, acting, actor = acting_of(H.tiny_config("a3c+maml", num_lanes=2))
    assert trainer.act_window is maml.act
    options = ActOptions(greedy=True, whole_episodes=True)
    assert maml.act(trainer.networks, acting, env, actor, jax.random.key(3), 3, options)[1:] == ("traj", "end")
    (got,) = adaptive
    assert got[0] is trainer.networks and got[5:7] == (3, options)
    assert got[1].noise_variance is not None and got[1].noise_variance.shape == (2,)
    assert len(calls) == 1  # no a3c window was run beside it


def test_noise_on_the_input_is_algorithm_1s_and_on_the_output_eq_6s():
    """The learned imagination's i_tau (`imagination.imagine`): f_w([s : g]) + eta by default
    (Eq. 6); with the noise on the input (`Config.imagination_noise='input'`),
    f_w([s : g] + eta) (Algorithm 1), eta from the same key and variance."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    import train_helpers as H
    from foresit_jax import imagination
    from foresit_jax.networks import build

    def imagine_fn(w, s, g):  # a nonlinear stand-in for f_w: where the noise enters matters
        return jnp.tanh(w * s + g.sum(-1, keepdims=True))

    def nets_of(noise):
        return dataclasses.replace(build(H.tiny_config("a3c+foresit", imagination_noise=noise)), imagine=imagine_fn)

    key, s_t, goal = jax.random.key(1), jnp.full((2, 4), 0.5), jnp.ones((2, 3))
    variance = jnp.array([0.3, 1.0])
    out = imagination.imagine(nets_of("output").imagination, 2.0, s_t, goal, key, variance, None)
    np.testing.assert_allclose(out, imagination.add_imagination_noise(key, imagine_fn(2.0, s_t, goal), variance))
    inside = imagination.imagine(nets_of("input").imagination, 2.0, s_t, goal, key, variance, None)
    np.testing.assert_allclose(inside, imagine_fn(2.0, *imagination.add_input_noise(key, s_t, goal, variance)))
    assert not np.allclose(inside, out)


@pytest.mark.slow
def test_training_with_the_noise_on_f_ws_input_runs_and_stays_finite():
    import train_helpers as H

    state, metrics = H.init_and_run(H.tiny_config("a3c+foresit", imagination_noise="input"), 0, 2)
    H.assert_tree_finite((state.params, state.imagination_params, metrics))
