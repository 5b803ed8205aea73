"""Wrappers (five-value legacy step, episode statistics, flat observations), a PureJaxRL-style loop, the
spaces and the default params."""

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from envs import catalog as C
from envs.wrappers import FlattenObservationWrapper, LegacyStepAPIWrapper, LogWrapper
from env_helpers import index_tree, to_numpy


class StubEnv:
    """Returns fixed flags so that the wrapper logic is checked without compiling an env."""

    num_actions = 6

    def __init__(self, terminated, truncated):
        self.flags = (terminated, truncated)

    def reset(self, key, params=None):
        return {"view": jnp.zeros(3)}, jnp.zeros((), jnp.int32)

    def step(self, key, state, action, params=None):
        terminated, truncated = (jnp.asarray(f) for f in self.flags)
        info = {"terminated": terminated, "truncated": truncated, "marker": jnp.int32(7)}
        return {"view": jnp.ones(3)}, state + action, jnp.float32(-0.01), terminated, truncated, info


@pytest.mark.parametrize("terminated, truncated", [(False, False), (True, False), (False, True), (True, True)])
def test_legacy_wrapper_gives_five_values_with_done_terminated_or_truncated(terminated, truncated):
    legacy = LegacyStepAPIWrapper(StubEnv(terminated, truncated))
    obs, state = legacy.reset(jax.random.key(0))
    out = legacy.step(jax.random.key(1), state, 2)
    assert len(out) == 5
    obs, state, reward, done, info = out
    assert bool(done) == (terminated or truncated)
    assert int(state) == 2 and reward == np.float32(-0.01) and int(info["marker"]) == 7
    assert bool(info["terminated"]) == terminated and bool(info["truncated"]) == truncated
    assert legacy.num_actions == 6  # everything else is forwarded to the wrapped env


class ScriptedEnv:
    """Ends an episode (successfully) every second step; the oracle length is 5, more than
    the episode took, so SPL must be capped at 1 by max(L, L_opt)."""

    def reset(self, key, params=None):
        return jnp.zeros(2), jnp.zeros((), jnp.int32)

    def step(self, key, state, action, params=None):
        state = state + 1
        ended = state % 2 == 0
        info = {"success": ended, "optimal_length": jnp.int32(5)}
        return jnp.zeros(2), state, jnp.float32(1.5), ended, jnp.array(False), info


@pytest.mark.parametrize("five_values", [False, True], ids=["six-value step", "five-value step"])
def test_log_wrapper_caps_spl_and_keeps_the_last_episode(five_values):
    env = LogWrapper(LegacyStepAPIWrapper(ScriptedEnv()) if five_values else ScriptedEnv())
    _, state = env.reset(jax.random.key(0))
    step = jax.jit(env.step)
    seen = []
    for t in range(5):
        out = step(jax.random.key(t), state, 0)
        assert len(out) == (5 if five_values else 6)
        state, info = out[1], out[-1]
        seen.append(tuple(float(info[f"returned_episode_{k}"]) for k in ("returns", "lengths", "success", "spl")))
        assert bool(info["returned_episode"]) == (t % 2 == 1)
    assert seen == [(0, 0, 0, 0), (3.0, 2, 1, 1.0), (3.0, 2, 1, 1.0), (3.0, 2, 1, 1.0), (3.0, 2, 1, 1.0)]
    assert float(state.episode_returns) == 1.5 and int(state.episode_lengths) == 1 and int(state.timestep) == 5


NUM_ENVS, NUM_STEPS = 16, 120
# Done is rare so that, with the training limit of 30, some episodes are truncated.
ACTION_PROBS = (0.4, 0.2, 0.2, 0.09, 0.09, 0.02)


@pytest.fixture(scope="module")
def purejaxrl_rollout(savn_kit):
    """A PureJaxRL-style loop: lax.scan over a vmapped batch of envs driven through the
    legacy wrapper (over the LogWrapper), jitted; random actions; training time limits."""
    base = savn_kit.env
    params = base.make_params("test", training=True)
    env = LegacyStepAPIWrapper(LogWrapper(base))

    def run(key):
        k_reset, key = jax.random.split(key)
        obsv, env_state = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(k_reset, NUM_ENVS), params)

        def env_step(carry, _):
            env_state, obsv, key = carry
            key, k_act, k_step = jax.random.split(key, 3)
            action = jax.random.choice(k_act, env.action_space(params).n, (NUM_ENVS,), p=jnp.array(ACTION_PROBS))
            obsv, env_state, reward, done, info = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
                jax.random.split(k_step, NUM_ENVS), env_state, action, params
            )
            return (env_state, obsv, key), (obsv, action, reward, done, info)

        return jax.lax.scan(env_step, (env_state, obsv, key), None, NUM_STEPS)[1]

    return base, jax.block_until_ready(jax.jit(run)(jax.random.key(3)))


def test_purejaxrl_style_loop_runs_under_jit(purejaxrl_rollout):
    """Right shapes and dtypes, all finite, done = terminated | truncated of the env."""
    base, (obsv, action, reward, done, info) = purejaxrl_rollout
    w, c = base.view_width, base.num_semantic + 1
    chex.assert_shape(obsv["view"], (NUM_STEPS, NUM_ENVS, 3, w, c))
    chex.assert_shape(obsv["target"], (NUM_STEPS, NUM_ENVS, 300))
    chex.assert_shape([action, reward, done, info["returned_episode_returns"]], (NUM_STEPS, NUM_ENVS))
    chex.assert_type([reward, done], [jnp.float32, bool])
    chex.assert_tree_all_finite((obsv, reward, info["returned_episode_returns"], info["returned_episode_spl"]))
    np.testing.assert_array_equal(done, info["terminated"] | info["truncated"])
    np.testing.assert_array_equal(done, info["returned_episode"])
    assert bool(info["truncated"].any()) and bool(info["terminated"].any())


def test_log_wrapper_statistics_match_a_hand_accumulation(purejaxrl_rollout):
    """At every episode end the returned return, length, success and SPL equal a hand
    accumulation over the rollout; between ends they hold their last value."""
    _, (_, _, reward, done, info) = purejaxrl_rollout
    reward, done, info = to_numpy((reward, done, info))
    ends = 0
    for lane in range(NUM_ENVS):
        ret, length, last = np.float32(0.0), 0, (0.0, 0, False, 0.0)
        optimal = info["optimal_length"][0, lane]
        for t in range(NUM_STEPS):
            ret = np.float32(ret + reward[t, lane])
            length += 1
            assert info["optimal_length"][t, lane] == optimal, "optimal_length changed within an episode"
            assert info["episode_length"][t, lane] == length
            if done[t, lane]:
                success = bool(info["success"][t, lane])
                assert success == (info["terminated"][t, lane] and reward[t, lane] == np.float32(5.0))
                last = (ret, length, success, success * optimal / max(length, optimal))
                ends += 1
            got = tuple(info[f"returned_episode_{k}"][t, lane] for k in ("returns", "lengths", "success", "spl"))
            np.testing.assert_allclose(got[0], last[0], rtol=1e-6, atol=1e-6, err_msg=f"lane {lane} step {t}")
            assert got[1:3] == last[1:3], (lane, t, got, last)
            np.testing.assert_allclose(got[3], last[3], rtol=1e-6, err_msg=f"lane {lane} step {t}")
            if done[t, lane]:
                ret, length = np.float32(0.0), 0
                if t + 1 < NUM_STEPS:
                    optimal = info["optimal_length"][t + 1, lane]
    assert ends > NUM_ENVS
    assert (info["success"] & done).any(), "some episodes should succeed, to check success and SPL"


# --------------------------------------------------------------------------- spaces / params
@pytest.mark.parametrize("kit_name", ["savn_kit", "org_kit"])
def test_spaces_match_observations(request, kit_name):
    kit = request.getfixturevalue(kit_name)
    env, params = kit.env, kit.params
    assert env.action_space(params).n == 6 and env.num_actions == 6
    actions = jax.vmap(env.action_space(params).sample)(jax.random.split(jax.random.key(0), 200))
    assert set(np.asarray(actions).tolist()) == set(range(6))
    space = env.observation_space(params)
    expected = {"view", "target"} | ({"detections"} if env.setup == "org" else set())
    assert set(space.spaces) == expected
    obs, _ = kit.reset_batch(jax.random.split(jax.random.key(1), 64))
    for i in (0, 17):
        o = index_tree(obs, i)
        for name, sub in space.spaces.items():
            assert o[name].shape == sub.shape and o[name].dtype == sub.dtype, name
        assert bool(space.contains(o))
    assert space["view"].shape == (3, env.view_width, 4 + len(C.categories(env.setup)) + 1)
    assert space["target"].shape == ((300,) if env.setup == "savn" else (22,))
    # The one-hot part sums to one per pixel; depth lies in (0, 1].
    view = obs["view"]
    np.testing.assert_array_equal(view[..., :-1].sum(-1), 1.0)
    assert (view[..., -1] > 0).all() and (view[..., -1] <= 1).all()
    sample = space.sample(jax.random.key(2))
    assert set(sample) == expected and sample["view"].shape == space["view"].shape


def test_default_params_work(savn_train_narrow):
    env = envs.GridNav(view_width=2)
    params = env.default_params
    _, train_params = savn_train_narrow
    np.testing.assert_array_equal(params.bank.numbers, C.scene_numbers("train"))
    np.testing.assert_array_equal(params.max_steps, [30, 30, 30, 30])
    chex.assert_trees_all_equal(params.bank, train_params.bank)
    assert env.name == "GridNav-v0"
    obs, state = env.reset(jax.random.key(0))  # params=None: the default params
    assert int(state.time) == 0 and obs["view"].shape == (3, 2, env.num_semantic + 1)
    obs, state, reward, terminated, truncated, info = env.step(jax.random.key(1), state, C.ROTATE_RIGHT)
    assert int(state.time) == 1 and reward == np.float32(-0.01) and not terminated


# --------------------------------------------------------------------------- flat observations
@pytest.mark.parametrize("kit_name", ["savn_kit", "org_kit"])
def test_flatten_wrapper_gives_one_float32_vector_in_the_documented_order(request, kit_name):
    kit = request.getfixturevalue(kit_name)
    base, params = kit.env, kit.params
    env = FlattenObservationWrapper(base)
    dict_space = base.observation_space(params)
    space = env.observation_space(params)
    n = envs.spaces.flat_size(dict_space)
    assert isinstance(space, envs.spaces.Box) and space.shape == (n,) and space.dtype == jnp.float32
    assert n == 3 * base.view_width * (base.num_semantic + 1) + dict_space["target"].shape[0] + (
        base.num_categories * 7 if base.setup == "org" else 0
    )
    keys = [k for k, *_ in env.layout(params)]
    assert keys == (["view", "target", "detections"] if base.setup == "org" else ["view", "target"])
    chex.assert_shape([space.low, space.high], (n,))
    view_size = int(np.prod(dict_space["view"].shape))
    assert (space.low[:view_size] == 0).all() and (space.high[:view_size] == 1).all()
    assert np.isinf(space.low[view_size : view_size + dict_space["target"].shape[0]]).all()

    obs, state = jax.jit(env.reset)(jax.random.key(0), params)
    dict_obs, _ = base.reset(jax.random.key(0), params)
    chex.assert_shape(obs, (n,))
    assert obs.dtype == jnp.float32 and bool(space.contains(obs))
    parts = [dict_obs[k].reshape(-1) for k in keys]
    np.testing.assert_array_equal(obs, np.concatenate(parts))  # row-major parts, in order
    chex.assert_trees_all_equal(env.unflatten(obs, params), dict_obs)
    # Batches: leading axes are kept.
    batch = jax.vmap(base.reset, in_axes=(0, None))(jax.random.split(jax.random.key(1), 3), params)[0]
    flat = env.flatten(batch, params)
    chex.assert_shape(flat, (3, n))
    chex.assert_trees_all_equal(env.unflatten(flat, params), batch)
    # Step: six values, the observation and info["final_observation"] flattened, the rest as is.
    out = jax.jit(env.step)(jax.random.key(2), state, C.DONE, params)
    ref = base.step(jax.random.key(2), state, C.DONE, params)
    assert len(out) == 6
    np.testing.assert_array_equal(out[0], env.flatten(ref[0], params))
    chex.assert_trees_all_equal(out[1:5], ref[1:5])
    info, ref_info = out[5], ref[5]
    np.testing.assert_array_equal(info["final_observation"], env.flatten(ref_info["final_observation"], params))
    np.testing.assert_array_equal(info["final_observation"], obs)  # Done: the last real observation
    chex.assert_trees_all_equal(
        {k: v for k, v in info.items() if k != "final_observation"},
        {k: v for k, v in ref_info.items() if k != "final_observation"},
    )


def test_flatten_wrapper_takes_a_five_value_step_and_box_observations():
    class BoxEnv(StubEnv):
        def observation_space(self, params=None):
            return envs.spaces.Box(0.0, np.arange(6.0).reshape(2, 3), (2, 3), jnp.int32)

        def reset(self, key, params=None):
            return jnp.arange(6, dtype=jnp.int32).reshape(2, 3), jnp.zeros((), jnp.int32)

        def step(self, key, state, action, params=None):
            obs, state, reward, terminated, truncated, info = super().step(key, state, action, params)
            return jnp.ones((2, 3), jnp.int32), state, reward, terminated, truncated, info

    env = FlattenObservationWrapper(LegacyStepAPIWrapper(BoxEnv(True, False)))
    space = env.observation_space()
    assert space.shape == (6,) and space.dtype == jnp.float32
    np.testing.assert_array_equal(space.high, np.arange(6.0))
    obs, state = env.reset(jax.random.key(0))
    np.testing.assert_array_equal(obs, np.arange(6.0))
    assert obs.dtype == jnp.float32
    obs, state, reward, done, info = env.step(jax.random.key(1), state, 1)
    np.testing.assert_array_equal(obs, np.ones(6))
    assert obs.dtype == jnp.float32 and bool(done) and int(info["marker"]) == 7 and int(state) == 1
    assert env.num_actions == 6


def test_wrappers_deepcopy_and_pickle_without_recursing_and_forward_the_rest():
    """copy and pickle build a wrapper without __init__ and look up dunder names on it
    before `_env` exists; the wrapper must answer those itself (it recursed forever before)."""
    import copy
    import pickle

    env, params = envs.make("GridNav-v0", room_types=("bathroom",), view_width=2)
    stack = LogWrapper(LegacyStepAPIWrapper(FlattenObservationWrapper(env)))
    for copied in (copy.copy(stack), copy.deepcopy(stack), pickle.loads(pickle.dumps(stack))):
        assert copied.name == "GridNav-v0" and copied.num_actions == 6  # forwarded to GridNav
        assert copied.observation_space(params).shape == stack.observation_space(params).shape
        obs, state = copied.reset(jax.random.key(0), params)
        np.testing.assert_array_equal(np.asarray(obs), np.asarray(stack.reset(jax.random.key(0), params)[0]))
    half_built = object.__new__(LogWrapper)  # what copy and pickle start from
    with pytest.raises(AttributeError):
        half_built.__setstate__
    with pytest.raises(AttributeError):
        half_built.name  # no _env yet: an AttributeError, not a RecursionError
