"""foresit_jax.methods: names parse into pieces; impossible combinations are clear errors;
gradient paths are declared per method and validated by Config."""

import dataclasses

import jax.numpy as jnp
import numpy as np
import pytest

from foresit_jax.config import Config
from foresit_jax.methods import IMAGINATION_VARIANTS, IMPLEMENTED_METHODS, PAPER_METHODS, Method, parse_method


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
        ("a3c", "plain", "a3c"), ("a3c+critic", "attention", "a3c+critic"),
        ("a3c+foresit", "attention", "a3c+foresit"), ("critic+foresit", "attention", "a3c+foresit"),
        ("a3c+foresit+plaincritic", "plain", "a3c+foresit+plaincritic"), ("a3c+plaincritic", "plain", "a3c"),
        ("org+rnd", "attention", "a3c+org+rnd"), ("plaincritic+org+rnd", "plain", "a3c+org+rnd+plaincritic"),
        ("a3c+maml+critic", "attention", "a3c+maml+critic"), ("a3c+org+int+plaincritic", "plain", "a3c+org+int+plaincritic"),
    ],
)  # fmt: skip
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
    [("a3c+ppo", "unknown piece 'ppo'"), ("foresit+rnd", "two imagination"),
     ("maml+maml", "two base"), ("", "non-empty")],
)  # fmt: skip
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
    np.testing.assert_array_equal(foresit.renews(steps, 10), steps == 0)
    np.testing.assert_array_equal(intv.renews(steps, 10), steps % 10 == 0)
    assert dataclasses.replace(foresit, name="x") != foresit  # frozen, comparable


def test_no_code_outside_the_pieces_tests_a_base_or_encoder_name():
    """Methods compose from the pieces' behaviour (`Base`, `Encoder`, `ImaginationVariant`
    records): outside foresit_jax/methods.py no module compares a base's or an
    encoder's name."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
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
def test_the_agent_acts_through_its_bases_act():
    """`Agent.act` is the base piece's `act` (here a3c's, wrapped to count its calls)."""
    import jax

    from foresit_jax import methods
    from foresit_jax.agent import ActOptions, Agent, AgentParams, BoundEnv
    from foresit_jax.train import make_env

    calls = []

    def counting(*args):
        calls.append(args[-1])  # the ActOptions
        return methods.act_in_windows(*args)

    config = Config(method="a3c", room_types=("bathroom",), num_lanes=2, num_steps=3, hidden_size=8,
                    attention_size=8, value_hidden=8, imagination_layer_sizes=(8, 8))  # fmt: skip
    pieces = dict(methods.BASE_PIECES, a3c=dataclasses.replace(methods.BASE_PIECES["a3c"], act=counting))
    original = methods.BASE_PIECES
    methods.BASE_PIECES = pieces
    try:
        agent = Agent(config)
        env, env_params = make_env(config)
        obs, _ = env.reset(jax.random.key(0), env_params)
        params, w_params = agent.init(jax.random.key(1), obs)
        env = BoundEnv(env, env_params)
        actor = agent.start(jax.random.key(2), env, 2)
        _, traj, _ = agent.act(AgentParams(params, w_params), env, actor, jax.random.key(3), 3, ActOptions(greedy=True))
    finally:
        methods.BASE_PIECES = original
    assert len(calls) == 1 and calls[0].greedy is True and traj.actions.shape == (3, 2)


def test_noise_on_the_input_is_algorithm_1s_and_on_the_output_eq_6s():
    """The learned imagination's i_tau: f_w([s : g]) + eta by default (Eq. 6); with the
    noise on the input, f_w([s : g] + eta) (Algorithm 1), eta from the same key and variance."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    from foresit_jax import imagination, methods

    def imagine_fn(w, s, g):  # a nonlinear stand-in for f_w: where the noise enters matters
        return jnp.tanh(w * s + g.sum(-1, keepdims=True))

    piece = methods.IMAGINATION_VARIANTS["foresit"]
    key, s_t, goal = jax.random.key(1), jnp.full((2, 4), 0.5), jnp.ones((2, 3))
    variance = jnp.array([0.3, 1.0])
    out = piece.imagine(imagine_fn, 2.0, s_t, goal, key, variance, 0.5)
    np.testing.assert_allclose(out, imagination.add_imagination_noise(key, imagine_fn(2.0, s_t, goal), variance))
    inside = piece.imagine(imagine_fn, 2.0, s_t, goal, key, variance, 0.5, noise_on_input=True)
    np.testing.assert_allclose(inside, imagine_fn(2.0, *imagination.add_input_noise(key, s_t, goal, variance)))
    assert not np.allclose(inside, out)


@pytest.mark.slow
def test_training_with_the_noise_on_f_ws_input_runs_and_stays_finite():
    import train_helpers as H

    state, metrics = H.init_and_run(H.tiny_config("a3c+foresit", imagination_noise="input"), 0, 2)
    H.assert_tree_finite((state.params, state.imagination_params, metrics))
