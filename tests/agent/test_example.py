"""examples/a3c_foresit.py, the one-file A3C+ForeSIT people copy, computes what the
Trainer computes for a3c+foresit: the same initial parameters from the same key, the same
window (actions), loss and gradient, and the same state after a run of whole updates
(parameters, f_w, buffers, success trackers), with f_w trained in them. The Trainer's
fast forms (split LSTM, GridDense, the while loop over full lanes) and the file's plain
ones agree to float rounding, so values are compared with tolerances; the actions, which a
rounding flip would change, exactly."""

import importlib.util
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from experiments.running import presets
from foresit_jax.train import make_trainer

# Trains the example and the Trainer side by side (about 50 s on a 2-core CPU).
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
WARMUP, UPDATES = 20, 30


def load_example():
    spec = importlib.util.spec_from_file_location("a3c_foresit", ROOT / "examples" / "a3c_foresit.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def pair():
    ex = load_example()
    # Small nets and buffers of 2, so that f_w trains within a few dozen updates.
    cfg, _ = presets.preset(
        "quick",
        "a3c+foresit",
        num_lanes=4,
        room_types=("bathroom",),
        buffer_size=2,
        imagination_epochs=2,
        hidden_size=32,
        attention_size=32,
        value_hidden=32,
        imagination_layer_sizes=(32, 16, 8, 16, 32, 32),
    )
    config = dict(
        ex.CONFIG,
        NUM_LANES=cfg.num_lanes,
        NUM_STEPS=cfg.num_steps,
        LR=cfg.learning_rate,
        HIDDEN=cfg.hidden_size,
        ATTENTION=cfg.attention_size,
        VALUE_HIDDEN=cfg.value_hidden,
        IMAGINATION_LAYERS=cfg.imagination_layer_sizes,
        BUFFER_SIZE=cfg.buffer_size,
        IMAGINATION_EPOCHS=cfg.imagination_epochs,
        ROOM_TYPES=cfg.room_types,
    )
    for name, value in [
        ("GAMMA", cfg.gamma),
        ("ENT_COEF", cfg.entropy_coef),
        ("VF_COEF", cfg.value_coef),
        ("MAX_GRAD_NORM", cfg.max_grad_norm),
        ("IMAGINATION_LR", cfg.imagination_lr),
        ("SIGMA2_MAX", cfg.sigma2_max),
        ("SUCCESS_WINDOW", cfg.success_window),
    ]:
        assert ex.CONFIG[name] == value, f"the example's {name} differs from the quick preset's"
    assert (cfg.imagination_optimizer, cfg.gae_lambda, cfg.rollout, cfg.gradient) == ("adam", 1.0, "packed", "replay")
    trainer = make_trainer(cfg)
    run = jax.jit(trainer.run, static_argnums=2)
    state = run(trainer.init(jax.random.key(0)), trainer.env_params, WARMUP)[0]
    return ex, config, trainer, run, state


def as_example_state(ex, state):
    """The Trainer's RunnerState as the example's (the same fields, the example's types)."""
    actor, agent = state.actor, state.actor.agent
    lanes = ex.Lanes(
        actor.env_state,
        actor.obs,
        agent.lstm,
        agent.prev_probs,
        agent.imagination.imagined,
        agent.imagination.s_0,
        agent.episode_step,
        actor.memory,
        ex.Tracker(*agent.imagination.tracker),
    )
    return ex.RunnerState(
        state.params, state.opt_state, state.imagination_params, ex.Buffers(*state.buffers), lanes, state.key
    )


def assert_trees_close(a, b, rtol=1e-4, scale=1e-5):
    """Leaf by leaf, to rtol and to `scale` times the tree's largest magnitude (a gradient
    that is zero in exact arithmetic, as the attention key's bias's, is rounding noise)."""
    a, b = jax.tree.leaves(a), jax.tree.leaves(b)
    assert len(a) == len(b)
    atol = scale * max(float(jnp.max(jnp.abs(x))) for x in a)
    for x, y in zip(a, b):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=rtol, atol=atol)


def test_the_example_initialises_the_trainers_parameters(pair):
    ex, config, trainer, _, _ = pair
    _, init, _, _ = ex.make_train(config)
    ours, theirs = init(jax.random.key(0)), trainer.init(jax.random.key(0))
    assert jax.tree.structure(ours.params) == jax.tree.structure(theirs.params)
    for a, b in zip(
        jax.tree.leaves((ours.params, ours.w_params)), jax.tree.leaves((theirs.params, theirs.imagination_params))
    ):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(ours.lanes.obs["view"], theirs.actor.obs["view"])


def test_the_examples_window_loss_and_gradient_are_the_trainers(pair):
    ex, config, trainer, _, state = pair
    _, _, _, loss_and_grad = ex.make_train(config)
    env = trainer.bind(trainer.env_params)
    actor, _, k_act = trainer.begin_window(state.actor, state.key, env)
    (loss, (_, traj, *_)), grads = jax.jit(trainer.loss_and_grad)(
        state.params, state.imagination_params, env, actor, k_act
    )
    mine = as_example_state(ex, state)
    (my_loss, (_, my_traj, _, _)), my_grads = jax.jit(loss_and_grad)(mine.params, mine.w_params, mine.lanes, k_act)
    np.testing.assert_array_equal(my_traj.action, traj.actions)
    np.testing.assert_array_equal(my_traj.done, traj.terminated | traj.truncated)
    np.testing.assert_allclose(my_traj.imagined, traj.inputs.imagined, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(my_loss, loss, rtol=1e-5)
    assert_trees_close(my_grads, grads)
    assert float(jnp.max(jnp.abs(grads["params"]["policy"]["actor"]["kernel"]))) > 0


def without_key_bias(params):
    critic = {k: v for k, v in params["params"]["value_critic"].items() if k != "key"}
    critic["key"] = {"kernel": params["params"]["value_critic"]["key"]["kernel"]}
    return {"params": {**params["params"], "value_critic": critic}}


def test_the_examples_updates_end_where_the_trainers_do(pair):
    """UPDATES whole updates from the same state: f_w trains in some of them (the buffers
    fill), and the parameters, f_w, buffers and success trackers end the same."""
    ex, config, trainer, run, state = pair
    _, _, update, _ = ex.make_train(config)
    theirs, metrics = run(state, trainer.env_params, UPDATES)
    ours, _ = jax.jit(lambda s: jax.lax.scan(update, s, None, UPDATES))(as_example_state(ex, state))
    assert float(metrics["imagination/num_trained_lanes"].sum()) >= 2
    # The attention key's bias adds q . b to every score of a row, which the softmax
    # ignores: its gradient is 0 in exact arithmetic and rounding noise in floats, and Adam
    # turns noise into steps of size lr. It follows the rounding, not the algorithm.
    assert_trees_close(without_key_bias(ours.params), without_key_bias(theirs.params), rtol=1e-3, scale=1e-4)
    assert_trees_close(ours.w_params, theirs.imagination_params, rtol=1e-3, scale=1e-4)
    assert_trees_close(tuple(ours.buffers), tuple(theirs.buffers), rtol=1e-3, scale=1e-4)
    for a, b in zip(ours.lanes.tracker, theirs.actor.agent.imagination.tracker):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(ours.lanes.episode_step, theirs.actor.agent.episode_step)
