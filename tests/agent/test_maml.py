"""The maml base (SAVN): the learned loss against numpy, the inner step against a
hand-written SGD step, when inner updates happen, that later steps really run under the
adapted parameters (recomputed independently with flax's own modules), and the
second-order meta-gradient against central finite differences in float64."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import traverse_util

import train_helpers as H
from foresit_jax import imagination, learned_loss, maml, rollout
from foresit_jax.evaluate import Evaluator
from foresit_jax.networks import ActorCritic, build
from foresit_jax.rollout import ActOptions, AgentParams, BoundEnv
from foresit_jax.train import Trainer

WHOLE = ActOptions(whole_episodes=True)  # the maml base acts in whole episodes


def _adaptive_act(nets, params, w_params, env, actor, key, num_steps, options=WHOLE):
    """`maml.adaptive_act` acting as training does: each lane's noise variance Eq. 7's
    from its success tracker (what `maml.act` fills in)."""
    rho = jax.vmap(imagination.success_rate)(actor.agent.imagination.tracker)
    acting = AgentParams(params, w_params, imagination.noise_variance(rho, nets.config.sigma2_max))
    return maml.adaptive_act(nets, acting, env, actor, key, num_steps, options)


# ---------------------------------------------------------------------- the learned loss
def _numpy_learned_loss(phi, inputs):
    """SAVN's ll_tc by loops: steps are channels, causal dilated convs over features."""
    x = np.asarray(inputs, np.float64).T  # [F, 6]
    for level, name in enumerate(("conv0", "conv1")):
        w = np.asarray(phi[name]["kernel"], np.float64)  # [k, in, out]
        b = np.asarray(phi[name]["bias"], np.float64)
        k, d = w.shape[0], 2**level
        pad = np.concatenate([np.zeros(((k - 1) * d, x.shape[1])), x], axis=0)
        y = np.zeros((x.shape[0], w.shape[2]))
        for j in range(x.shape[0]):
            for t in range(k):
                y[j] += pad[j + t * d] @ w[t]
        y += b
        x = np.where(y > 0, y, 0.01 * y)
    return np.sqrt(np.sum(x**2))


def test_learned_loss_matches_numpy_and_is_causal_over_features():
    module = learned_loss.LearnedLoss(segment=6)
    inputs = jax.random.normal(jax.random.PRNGKey(1), (6, 22))
    phi = module.init(jax.random.PRNGKey(0), inputs)
    assert phi["params"]["conv0"]["kernel"].shape == (2, 6, 10)  # 6 steps -> 10 channels, kernel 2
    assert phi["params"]["conv1"]["kernel"].shape == (2, 10, 1)
    got = float(module.apply(phi, inputs))
    np.testing.assert_allclose(got, _numpy_learned_loss(phi["params"], inputs), rtol=1e-5)
    with pytest.raises(ValueError, match="expects 6 steps"):
        module.apply(phi, inputs[:5])


@pytest.mark.parametrize("dilation", [1, 2])
def test_causal_conv_is_flax_conv_with_causal_padding(dilation):
    """The same parameters (names, shapes, init values) and outputs as nn.Conv (which
    cannot be partitioned in a3c+maml's sharded seed sweep: see
    tests/experiments/test_sweep_cli.py::test_a_sweep_spread_over_two_host_devices_equals_the_one_device_sweep)."""
    import flax.linen as nn

    init = learned_loss._torch_default_init(12)
    x = jax.random.normal(jax.random.PRNGKey(1), (20, 6))
    ours = learned_loss.CausalConv1d(10, 2, dilation, init)
    flax_conv = nn.Conv(
        10, (2,), kernel_dilation=(dilation,), padding=((dilation, 0),), kernel_init=init, bias_init=init
    )
    p_ours, p_flax = ours.init(jax.random.PRNGKey(0), x), flax_conv.init(jax.random.PRNGKey(0), x)
    jax.tree.map(np.testing.assert_array_equal, p_ours, p_flax)
    np.testing.assert_allclose(ours.apply(p_ours, x), flax_conv.apply(p_flax, x), rtol=1e-5, atol=1e-6)


def test_inner_step_is_sgd_on_everything_but_phi():
    params = {
        "params": {
            "encoder": {"w": jnp.ones((2, 3))},
            "actor": {"b": jnp.arange(3.0)},
            "learned_loss": {"conv0": {"kernel": jnp.ones((2, 6, 10))}},
        }
    }
    grads = jax.tree.map(lambda x: jnp.full_like(x, 2.0), params)
    new = maml.inner_step(params, grads, 0.1)
    np.testing.assert_allclose(new["params"]["encoder"]["w"], np.ones((2, 3)) - 0.2)
    np.testing.assert_allclose(new["params"]["actor"]["b"], np.arange(3.0) - 0.2)
    H.assert_trees_bitwise_equal(new["params"]["learned_loss"], params["params"]["learned_loss"])
    H.assert_trees_bitwise_equal(maml.inner_step(params, grads, 0.1, jnp.asarray(False)), params)


def test_update_slots_are_savns():
    assert maml.update_steps(30, 6, 4) == (6, 12, 18, 24)
    assert maml.update_steps(200, 6, 4) == (6, 12, 18, 24)
    assert maml.update_steps(14, 6, 4) == (6, 12)
    assert maml.update_steps(30, 6, 0) == ()
    assert maml.update_steps(24, 6, 4) == (6, 12, 18)  # none after the last step: nothing would act under it


# ---------------------------------------------------------------------- the inner loop
def _setup(lr=0.05, lanes=16, training=True, never_done=False, **overrides):
    config = H.tiny_config("a3c+maml", num_lanes=lanes, maml_inner_lr=lr, **overrides)
    env, env_params = H.bathroom_env("train", training)
    nets = build(config)
    obs, _ = env.reset(jax.random.PRNGKey(0), env_params)
    params, w_params = nets.init(jax.random.PRNGKey(3), obs)
    if never_done:  # the Done action never sampled: every episode runs to the time limit
        params = jax.tree.map(lambda x: x, params)
        params["params"]["policy"]["actor"]["bias"] = params["params"]["policy"]["actor"]["bias"].at[5].set(-30.0)
    actor = rollout.start(nets, jax.random.PRNGKey(4), BoundEnv(env, env_params), lanes)
    return config, nets, env, env_params, params, w_params, actor


@pytest.fixture(scope="module")
def adapted_rollout():
    config, nets, env, env_params, params, w_params, actor = _setup()
    run = jax.jit(
        lambda p, a, k: _adaptive_act(nets, p, w_params, BoundEnv(env, env_params), a, k, 30),
        compiler_options=H.FAST_COMPILE,
    )
    _, traj, _, thetas = run(params, actor, jax.random.PRNGKey(5))
    return config, params, traj, thetas


@pytest.mark.slow
def test_inner_updates_only_after_steps_6_12_18_24_of_running_episodes(adapted_rollout):
    config, params, traj, thetas = adapted_rollout
    assert len(thetas) == 1 + 4  # theta_0, then one slot after each of steps 6, 12, 18, 24
    running = np.asarray(traj.valid & ~(traj.terminated | traj.truncated))  # [T, B] episode goes on after step t
    flat = [traverse_util.flatten_dict(jax.tree.map(np.asarray, t.dense())) for t in thetas]
    lanes = running.shape[1]
    updated_any = np.zeros(lanes, bool)
    for i in range(1, 5):
        goes_on = running[6 * i - 1]  # alive after step 6 i
        for b in range(lanes):
            changed = any(not np.array_equal(flat[i][p][b], flat[i - 1][p][b]) for p in flat[0] if maml.adapts(p))
            assert changed == bool(goes_on[b]), (i, b)
            updated_any[b] |= changed
        for p in flat[0]:  # phi and the critic never change in an inner step
            if not maml.adapts(p) or "value_critic" in p:
                np.testing.assert_array_equal(flat[i][p], flat[0][p])
    assert updated_any.any() and not updated_any.all(), "seed should mix short and long episodes"
    # Steps are counted from the episode's start: every lane's counted episode starts at 0.
    np.testing.assert_array_equal(np.asarray(traj.episode_step)[0], 0)


@pytest.mark.slow
def test_evaluation_step_13_runs_under_theta_2_recomputed_independently():
    """An evaluation episode (time limit 100; its first 14 steps): recompute theta_1 = theta_0 - lr grad L_phi
    (steps 0-5 under theta_0) and theta_2 (steps 6-11 under theta_1) with flax's own
    modules over the recorded observations, then step 13's logits under
    theta_2; they match the rollout's and differ from theta_0's."""
    config, nets, env, env_params, params, w_params, actor = _setup(lr=5.0, lanes=4, training=False, never_done=True)
    run = jax.jit(
        lambda p, a, k: _adaptive_act(nets, p, w_params, BoundEnv(env, env_params), a, k, 14),
        compiler_options=H.FAST_COMPILE,
    )
    _, traj, _, thetas = run(params, actor, jax.random.PRNGKey(6))
    assert bool(np.all(np.asarray(traj.valid)[:14]))  # every lane still in its episode at step 13
    lane = 1
    lane_inputs = jax.tree.map(lambda x: x[:, lane], traj.inputs)
    carry0 = (jnp.zeros(config.hidden_size), jnp.zeros(config.hidden_size))

    def run_steps(theta, carry, start, stop):
        """Steps start..stop-1 under theta by flax's own step, each step's action
        probabilities fed to the next (SAVN's graph); the first step's recorded ones
        come from earlier parameters."""
        probs, states, logits = lane_inputs.prev_action_probs[start], [], []
        for t in range(start, stop):
            obs = jax.tree.map(lambda x: x[t], lane_inputs.obs)
            carry, s_t, logit, _ = nets.model.apply(theta, carry, obs, probs, None)  # flax's own cell
            probs = jax.nn.softmax(logit)
            states.append(s_t)
            logits.append(logit)
        return carry, jnp.stack(states), jnp.stack(logits)

    def segment_loss(theta, carry, start):
        _, states, logits = run_steps(theta, carry, start, start + 6)
        return nets.model.apply(theta, maml.interaction_inputs(states, logits), method=ActorCritic.interaction_loss)

    lr = config.maml_inner_lr
    theta_1 = maml.inner_step(params, jax.grad(segment_loss)(params, carry0, 0), lr)
    carry6, _, _ = run_steps(params, carry0, 0, 6)
    theta_2 = maml.inner_step(theta_1, jax.grad(segment_loss)(theta_1, carry6, 6), lr)
    carry12, _, _ = run_steps(theta_1, carry6, 6, 12)
    _, states_2, logits_2 = run_steps(theta_2, carry12, 12, 14)
    _, states_0, logits_0 = run_steps(params, carry0, 0, 14)
    np.testing.assert_allclose(traj.states[13, lane], states_2[1], rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(traj.logits[13, lane], logits_2[1], rtol=1e-4, atol=1e-6)
    # Adaptation happened: theta_0 alone gives other values (100x the tolerance).
    assert np.max(np.abs(np.asarray(states_2[1] - states_0[13]))) > 1e-3
    assert np.max(np.abs(np.asarray(logits_2[1] - logits_0[13]))) > 1e-4
    mine = jax.tree.map(lambda x: x[lane], thetas[2].dense())
    jax.tree.map(lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-6), mine, theta_2)


@pytest.mark.slow
def test_agent_rollout_adapts_through_the_same_code_path(monkeypatch):
    """Evaluation (the Evaluator's `rollout.rollout`) and training (the Trainer's window) both
    run adaptive_act through `maml.act`, the base's window that both choose (traced only:
    what is compiled is what is traced); packed windows are refused."""
    config, nets, env, env_params, params, w_params, actor = _setup(lanes=4, training=False)
    calls, bound = [], BoundEnv(env, env_params)
    real = maml.adaptive_act

    def spy(*args, **kwargs):
        calls.append(args[5])  # num_steps
        return real(*args, **kwargs)

    monkeypatch.setattr(maml, "adaptive_act", spy)
    key = jax.random.PRNGKey(7)
    evaluation = Evaluator.for_config(config).agent_rollout(config, 20, greedy=False)
    stats = jax.eval_shape(evaluation, params, w_params, env_params, key, jnp.zeros(4))
    assert calls == [20] and stats.success.shape == (4,)
    trainer = Trainer(config)
    assert trainer.act_window is maml.act
    jax.eval_shape(lambda p: trainer.act(AgentParams(p, w_params), bound, actor, key), params)
    assert calls == [20, config.num_steps]
    with pytest.raises(ValueError, match="whole episodes"):
        maml.act(nets, AgentParams(params, w_params), bound, actor, key, 5)  # packed windows: refused
    with pytest.raises(ValueError, match="act=foresit_jax.maml.act"):  # a3c's window would not adapt: refused
        rollout.rollout(nets, AgentParams(params, w_params, jnp.zeros(4)), bound, key, 20)
    with pytest.raises(ValueError, match="use foresit_jax.maml.act"):  # nor one window of it
        rollout.act_window(nets, AgentParams(params, w_params, jnp.zeros(4)), bound, actor, key, 20, WHOLE)


# ---------------------------------------------------------------------- the meta-gradient
def _meta_objective(first_order: bool):
    """A smooth function of an adapted episode's first 13 steps (inner updates after steps
    6 and 12), J(theta_0, phi) = sum of fixed random weights times every valid step's
    logits and states. (The A3C loss itself holds
    stop-gradients, the advantage's, so its gradient is not the derivative of its value;
    the trainer differentiates it through the same adaptive rollout.)"""
    config = H.tiny_config("a3c+maml", maml_inner_lr=0.5, maml_first_order=first_order, num_lanes=3)
    env, env_params = H.bathroom_env()
    nets = build(config)
    obs, _ = env.reset(jax.random.PRNGKey(0), env_params)
    params, w_params = nets.init(jax.random.PRNGKey(2), obs)
    # Off the initial zero biases: a ReLU of exactly 0 (zero bias, zero input) has no
    # derivative, and central differences would see half its slope.
    rng = np.random.default_rng(1)
    params = jax.tree.map(lambda x: x.astype(jnp.float64) + 0.05 * rng.standard_normal(x.shape), params)
    actor = rollout.start(nets, jax.random.PRNGKey(3), BoundEnv(env, env_params), config.num_lanes)
    f64 = lambda x: x.astype(jnp.float64)  # noqa: E731  the agent's own carries, in float64
    agent = actor.agent
    carry = agent.imagination._replace(imagined=f64(agent.imagination.imagined), s_0=f64(agent.imagination.s_0))
    agent = agent._replace(lstm=jax.tree.map(f64, agent.lstm), prev_probs=f64(agent.prev_probs), imagination=carry)
    actor = actor._replace(agent=agent)
    steps = 13
    w_logits = jnp.asarray(rng.standard_normal((steps, 3, 6)))
    w_states = jnp.asarray(rng.standard_normal((steps, 3, config.hidden_size)))

    def objective(p):
        _, traj, _, _ = _adaptive_act(
            nets,
            p,
            w_params,
            BoundEnv(env, env_params),
            actor,
            jax.random.PRNGKey(11),
            steps,
            WHOLE._replace(record_inputs=False),
        )
        valid = traj.valid[..., None]
        return jnp.sum(jnp.where(valid, traj.logits * w_logits, 0.0)) + jnp.sum(
            jnp.where(valid, traj.states * w_states, 0.0)
        )

    return jax.jit(jax.value_and_grad(objective), compiler_options=H.FAST_COMPILE), params


def enable_x64():
    """float64 inside a `with`: `jax.enable_x64(True)` where jax has it (0.10 does, and
    has no `jax.experimental.enable_x64`; 0.7 has only the latter)."""
    return jax.enable_x64(True) if hasattr(jax, "enable_x64") else jax.experimental.enable_x64()


@pytest.mark.slow
def test_meta_gradient_matches_finite_differences_and_has_its_second_order_term():
    with enable_x64():
        value_and_grad, params = _meta_objective(first_order=False)
        objective = lambda p: value_and_grad(p)[0]  # noqa: E731  (one compiled program)
        value, grads = value_and_grad(params)
        assert grads["params"]["encoder"]["lstm"]["hi"]["kernel"].dtype == jnp.float64
        rng = np.random.default_rng(0)
        phi_only = lambda t: {
            "params": {
                k: (v if k == "learned_loss" else jax.tree.map(jnp.zeros_like, v))  # noqa: E731
                for k, v in t["params"].items()
            }
        }
        for trial in range(3):
            direction = jax.tree.map(lambda x: jnp.asarray(rng.standard_normal(x.shape)), params)
            if trial == 2:  # phi alone: it gets its gradient only through the inner updates
                direction = phi_only(direction)
            eps = 1e-7  # float64: truncation ~eps^2 (measured 1e-3 relative at 1e-6), rounding ~1e-16/eps
            plus = objective(jax.tree.map(lambda p, d: p + eps * d, params, direction))
            minus = objective(jax.tree.map(lambda p, d: p - eps * d, params, direction))
            numeric = (float(plus) - float(minus)) / (2 * eps)
            analytic = sum(float(jnp.vdot(g, d)) for g, d in zip(jax.tree.leaves(grads), jax.tree.leaves(direction)))
            assert abs(numeric - analytic) <= 1e-4 * max(1.0, abs(numeric)), (trial, numeric, analytic)
            assert abs(analytic) > 1e-6
        # First-order MAML stops the inner gradient's gradient: phi gets none, and theta_0's
        # gradient changes (the second-order term is really there).
        first_value_and_grad, _ = _meta_objective(first_order=True)
        first_value, first_grads = first_value_and_grad(params)
        np.testing.assert_allclose(float(first_value), float(value), rtol=1e-12)
        phi_norm = lambda g: float(sum(jnp.sum(x**2) for x in jax.tree.leaves(g["params"]["learned_loss"])))  # noqa: E731
        assert phi_norm(grads) > 0 and phi_norm(first_grads) == 0.0
        diff = max(float(jnp.max(jnp.abs(a - b))) for a, b in zip(jax.tree.leaves(grads), jax.tree.leaves(first_grads)))
        assert diff > 1e-6


def test_config_requires_whole_episodes_through_the_rollout():
    with pytest.raises(ValueError, match="rollout"):
        H.tiny_config("a3c+maml", rollout="packed")
    with pytest.raises(ValueError, match="gradient"):
        H.tiny_config("a3c+maml", gradient="replay")
    config = H.tiny_config("a3c+maml+foresit")
    assert (config.rollout, config.gradient) == ("episodes", "through_rollout")
    assert dataclasses.replace(config, maml_first_order=True).maml_first_order


# ---------------------------------------------------------------------- training
@pytest.mark.slow
def test_maml_foresit_trains_without_nan_and_phi_learns():
    """a3c+maml+foresit (a3c+maml trains in the easy-setting test below)."""
    config = H.tiny_config("a3c+maml+foresit")
    state, metrics = H.init_and_run(config, 0, 2)
    H.assert_tree_finite(state)
    H.assert_tree_finite(metrics)
    init = H.jitted_init(config)(jax.random.PRNGKey(0))
    # The meta-gradient reaches phi (through the inner updates) and the optimiser moves it.
    assert not H.trees_bitwise_equal(state.params["params"]["learned_loss"], init.params["params"]["learned_loss"])
    assert float(np.min(metrics["charts/useful_fraction"])) < 1.0  # whole, padded episodes


@pytest.mark.slow
@pytest.mark.timeout(400)
def test_maml_training_on_an_easy_setting_raises_the_success_rate():
    """As the a3c easy-setting test (one bathroom, starts within 3 actions), with SAVN's
    inner loop in every training episode."""
    config = H.tiny_config(
        "a3c+maml",
        num_lanes=8,
        hidden_size=64,
        attention_size=64,
        value_hidden=64,
        imagination_layer_sizes=(64, 32, 16, 32, 64, 64),
        learning_rate=5e-3,
    )
    state, final, first, last = H.easy_setting_run(config, *H.bathroom_env())
    assert last > 0.5 and last > first + 0.25, (first, last)
    H.assert_tree_finite(final)
    assert not H.trees_bitwise_equal(final.params["params"]["learned_loss"], state.params["params"]["learned_loss"])


@pytest.mark.slow
def test_maml_evaluation_runs_its_episodes_in_groups(monkeypatch):
    """Groups of at most MAX_ADAPTIVE_LANES episodes (the last padded), playing the
    episodes one rollout of all lanes plays: those of every other method and of the
    random policy with the same key."""
    import importlib

    ev = importlib.import_module("foresit_jax.evaluate")  # the module (the package exports the function)

    assert ev.group_layout(250, 50) == (5, 50) and ev.group_layout(25, 50) == (1, 25)
    assert (
        ev.group_layout(7, 5) == (2, 4) and ev.group_layout(53, 50) == (2, 27) and ev.group_layout(12, None) == (1, 12)
    )
    monkeypatch.setattr(ev, "MAX_ADAPTIVE_LANES", 2)
    config, nets, env, env_params, params, w_params, actor = _setup(lanes=5, training=False)
    evaluator = ev.Evaluator(config.setup)
    run = evaluator.agent_rollout(config, 8, False)
    room = evaluator.room_params("val", "bathroom")
    key = jax.random.PRNGKey(0)
    outcomes = run(params, w_params, room, key, jnp.zeros(5))  # 3 groups of 2, one lane of padding
    assert outcomes.length.shape == (5,)
    # The same episodes as the random policy's (and any one-group rollout's) with this key:
    # the same starts, so the same optimal lengths.
    random = ev.random_policy_rollout(evaluator.env, room, key, 5, 8)
    np.testing.assert_array_equal(outcomes.optimal_length, random.optimal_length)
    assert len(set(np.asarray(random.optimal_length).tolist())) > 1  # (distinct episodes: the check can fail)
    # Group g: one rollout of its lanes' reset keys, acting with the g-th split of the key.
    k_start, k_act = jax.random.split(key)
    reset = jax.random.split(k_start, 5)
    group = jax.jit(
        lambda k, r: ev.episode_stats(
            rollout.rollout(
                nets,
                AgentParams(params, w_params, 0.0),
                BoundEnv(evaluator.env, room),
                k,
                8,
                reset_keys=r,
                act=maml.act,
            )
        ),
        compiler_options=H.FAST_COMPILE,
    )
    for g, k in enumerate(jax.random.split(k_act, 3)):
        lanes = slice(2 * g, min(2 * g + 2, 5))
        stats = group(k, jnp.concatenate([reset, reset[:1]])[2 * g : 2 * g + 2])
        n = lanes.stop - lanes.start
        np.testing.assert_array_equal(outcomes.length[lanes], stats.length[:n])
        np.testing.assert_array_equal(outcomes.success[lanes], stats.success[:n])
