"""Issue 80, item 4: the library's boundary is checked before anything acts. A policy given to
`evaluate_policy` that returns the wrong thing, a state given to `make_act` under another
Config, and a seed that is not an int are each refused in one line saying what was expected
and what came, not inside JAX's scan or vmap or by flax at the first act."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import experiments
import train_helpers as H
from experiments.errors import UserError
from experiments.running import models  # noqa: F401  (imported here, not timed in a test: experiments.load's)
from foresit_jax.evaluate import evaluate_policy, make_act
from foresit_jax.train import make_trainer

LANES = 3  # episodes per room: the lanes a policy acts for


def _config():
    return H.tiny_config("a3c")


def _evaluate(policy, initial_carry=lambda n: jnp.zeros((n,)), **kw):
    return evaluate_policy(policy, None, initial_carry, _config(), "test", episodes_per_room=LANES, **kw)


def _one_line(error) -> str:
    text = str(error)
    assert "\n" not in text, text
    return text


@pytest.mark.parametrize(
    "policy, kind, says",
    [
        # no carry: the actions alone
        (lambda p, c, o, f, k: jnp.zeros((LANES,), jnp.int32), TypeError, "returned an array of shape (3,)"),
        # three values
        (lambda p, c, o, f, k: (jnp.zeros((LANES,), jnp.int32), c, c), TypeError, "returned a tuple of 3 values"),
        # a scalar action
        (lambda p, c, o, f, k: (jnp.int32(0), c), ValueError, "got shape () (a scalar"),
        # one action too many per lane
        (lambda p, c, o, f, k: (jnp.zeros((LANES, 1), jnp.int32), c), ValueError, "got shape (3, 1)"),
        # float actions
        (lambda p, c, o, f, k: (jnp.zeros((LANES,)), c), TypeError, "integer dtype"),
        # bool actions
        (lambda p, c, o, f, k: (jnp.zeros((LANES,), bool), c), TypeError, "got bool"),
        # the carry dropped
        (lambda p, c, o, f, k: (jnp.zeros((LANES,), jnp.int32), None), TypeError, "must return the carry"),
        # the carry of another shape
        (lambda p, c, o, f, k: (jnp.zeros((LANES,), jnp.int32), c[:1]), TypeError, "has shape (1,)"),
    ],
    ids=["no-carry", "three-values", "scalar", "2d", "float", "bool", "carry-dropped", "carry-shape"],
)
def test_evaluate_policy_refuses_a_bad_return_in_one_line(policy, kind, says):
    with pytest.raises(kind) as error:
        _evaluate(policy)
    line = _one_line(error.value)
    assert line.startswith("evaluate_policy: "), line
    assert says in line, line
    assert "(actions [3]" in line or "shape (3,)" in line or "carry" in line or "integer" in line


def test_evaluate_policy_refuses_a_policy_that_cannot_take_its_five_arguments():
    with pytest.raises(TypeError, match=r"must take 5 arguments \(params, carry, obs, first, key\)") as error:
        _evaluate(lambda obs, key: (jnp.zeros((LANES,), jnp.int32), None))
    _one_line(error.value)
    with pytest.raises(TypeError, match="initial_carry must be a function"):
        _evaluate(lambda p, c, o, f, k: (jnp.zeros((LANES,), jnp.int32), c), initial_carry=jnp.zeros((LANES,)))


@pytest.mark.slow  # compiles a whole episode's scan (~5-9 s on 2 cores)
def test_evaluate_policy_check_actions_raises_on_an_action_outside_0_to_5():
    """`check_actions=True` (as `envs.make_gymnax(..., check_actions=True)`): an action 7 is
    refused at run time; without it, a step that changes nothing (GridNav's rule)."""
    policy = lambda p, c, o, f, k: (jnp.full((LANES,), 7, jnp.int32), c)  # noqa: E731
    with pytest.raises(Exception, match=r"the policy chose action 7, outside 0..5"):
        _evaluate(policy, check_actions=True)


def test_evaluate_policy_states_its_unit_and_keeps_its_keys():
    """SR and SPL in percent, said in the docstring; the return's keys are `summarize`'s."""
    doc = " ".join(evaluate_policy.__doc__.split())
    assert "in percent" in doc and '"SR", "SPL"' in doc and "check_actions" in doc


# ---------------------------------------------------------------------- make_act and load
@pytest.fixture(scope="module")
def zeros_state():
    """A RunnerState of `_config()` (hidden size 16) as zeros, by its shapes (nothing trains)."""
    trainer = make_trainer(_config())
    shapes = jax.eval_shape(trainer.init, jax.random.PRNGKey(0))
    return jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), shapes)


def test_make_act_refuses_a_state_of_another_config_in_one_line(zeros_state):
    """Today flax raised ScopeParamShapeError at the first act; now make_act names the
    first parameter whose shape differs, and the fix."""
    make_act(_config(), zeros_state)  # its own config: fine
    other = H.tiny_config("a3c", hidden_size=24, imagination_layer_sizes=(16, 8, 4, 8, 16, 24))
    with pytest.raises(
        ValueError, match=r"make_act: the state's parameters do not match the config: .* has shape"
    ) as e:
        make_act(other, zeros_state)
    line = _one_line(e.value)
    assert "the config's networks have" in line and "hidden_size 24" in line, line
    foresit = H.tiny_config("a3c+foresit")  # another method: another tree (the imagination input)
    with pytest.raises(ValueError, match="do not match the config"):
        make_act(foresit, zeros_state)


@pytest.mark.parametrize("seed", [0.0, 1.0, True, "0", np.float32(0)])
def test_make_act_refuses_a_seed_that_is_not_an_int(zeros_state, seed):
    """A float seed passed `0 <= seed < n` and failed inside JAX's indexing."""
    with pytest.raises(ValueError, match="make_act: seed must be an int") as e:
        make_act(_config(), zeros_state, seed=seed)
    _one_line(e.value)


def test_make_act_takes_a_numpy_int_seed(zeros_state):
    stacked = jax.tree.map(lambda x: jnp.stack([x, x]), zeros_state)
    assert make_act(_config(), stacked, seed=np.int64(1)).config == _config()


@pytest.mark.parametrize("seed", [0.0, True, "0", None])
def test_load_refuses_a_seed_that_is_not_an_int_before_reading_the_run(tmp_path, seed):
    """`experiments.load(run, seed=0.0)` passed the check (0.0 == 0) and failed inside JAX."""
    (tmp_path / "run.json").write_text(json.dumps({"not": "read"}))  # never read: the seed is refused first
    with pytest.raises(UserError, match="seed must be an int") as e:
        experiments.load(tmp_path, seed=seed)
    _one_line(e.value)
