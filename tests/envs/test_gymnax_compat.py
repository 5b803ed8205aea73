"""envs.make_gymnax: GridNav as gymnax.make returns an environment (flat float32
observations, gymnax's spaces, one fixed step convention by default, five values, whatever
is installed, cached default params, gymnax 1.x Environment's members), checked against
GridNav itself; and the registration with gymnax's registry.  The
tests that need gymnax are skipped with a reason without it (CI installs it on both stacks: the dev extra on Python 3.11, without its jax cap on 3.13).
The PPO loops over it are tests/envs/test_purejaxrl_ppo.py."""

import contextlib
import subprocess
import sys
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from envs import catalog as C
from envs import gymnax_compat
from envs import spaces as own_spaces
from envs.wrappers import FlattenObservationWrapper

GYMNAX = gymnax_compat.installed_gymnax_version()
needs_gymnax = pytest.mark.skipif(GYMNAX is None, reason="gymnax is not installed (pip install -e '.[gymnax]')")
needs_gymnax_1 = pytest.mark.skipif(GYMNAX is None or GYMNAX < (1,), reason="needs gymnax >= 1.0 (its registry)")
ROOMS = ("bathroom",)


@contextlib.contextmanager
def no_warning():
    """Expects no warning of the project's at all: a new user's make_gymnax is silent
    (issue 71), whatever gymnax is installed and whether or not step_api is passed."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    future = [w for w in caught if issubclass(w.category, FutureWarning) or "step_api" in str(w.message)]
    assert not future, [f"{w.category.__name__}: {w.message}" for w in future]


@pytest.fixture(scope="module")
def pair():
    """The five- and six-value forms over one scene bank, and GridNav itself."""
    five, params = envs.make_gymnax(room_types=ROOMS, step_api="done", final_observation=True)
    six = gymnax_compat.GymnaxGridNav(five.gridnav, params, "terminated_truncated")
    return five, six, params


def rollout(env, params, actions, key=0):
    """Steps ``env`` (one lane) through ``actions``; returns each step's outputs (numpy)."""
    obs, state = env.reset(jax.random.key(key), params)
    outs = [(np.asarray(obs),)]
    for t, action in enumerate(actions):
        out = env.step(jax.random.key(1000 + t), state, jnp.int32(action), params)
        state = out[1]
        outs.append(jax.tree.map(np.asarray, (out[0], *out[2:])))
    return outs


def test_both_conventions_step_as_gridnav_does(pair):
    """Same keys and actions: the observation is GridNav's, flattened; the five-value step's
    done is terminated | truncated of the six-value one; the rest is identical."""
    five, six, params = pair
    flat = FlattenObservationWrapper(five.gridnav)
    # Done at once ends an episode; then a walk long enough to hit the 30-step limit.
    actions = [5] + [0, 1, 0, 2, 3, 4] * 6
    a, b = rollout(five, params, actions), rollout(six, params, actions)
    obs, state = five.gridnav.reset(jax.random.key(0), params)
    np.testing.assert_array_equal(a[0][0], np.asarray(flat.flatten(obs)))
    np.testing.assert_array_equal(a[0][0], b[0][0])
    ends = 0
    for t, action in enumerate(actions, start=1):
        obs_g, state, reward_g, term, trunc, info_g = five.gridnav.step(
            jax.random.key(1000 + t - 1), state, jnp.int32(action), params
        )
        obs5, reward5, done5, info5 = a[t]
        obs6, reward6, term6, trunc6, info6 = b[t]
        np.testing.assert_array_equal(obs5, np.asarray(flat.flatten(obs_g)))
        np.testing.assert_array_equal(obs5, obs6)
        assert reward5 == reward6 == np.asarray(reward_g)
        assert (bool(term6), bool(trunc6)) == (bool(term), bool(trunc))
        assert bool(done5) == bool(term6 | trunc6)
        ends += bool(done5)
        np.testing.assert_array_equal(info5["final_observation"], np.asarray(flat.flatten(info_g["final_observation"])))
        for key in ("success", "episode_length", "optimal_length", "room_type", "terminated", "truncated"):
            assert info5[key] == info6[key] == np.asarray(info_g[key]), key
    assert bool(a[1][2]) and ends == 2  # the Done, then the 30-step training limit


def test_the_observation_is_flat_float32_inside_its_box(pair):
    five, _, params = pair
    space = five.observation_space(params)
    obs, state = five.reset(jax.random.key(3), params)
    assert obs.dtype == jnp.float32 and obs.shape == space.shape == (3 * 16 * (4 + 18 + 1) + 300,)
    assert bool(space.contains(obs))
    assert five.action_space(params).n == five.num_actions == 6
    assert five.name == "GridNav-v0"
    np.testing.assert_array_equal(five.get_obs(state, params), obs)


def test_final_observation_by_default_only_with_six_values():
    five, params = envs.make_gymnax(room_types=ROOMS, step_api="done")
    six, _ = envs.make_gymnax(room_types=ROOMS, step_api="terminated_truncated")
    _, state = five.reset(jax.random.key(0), params)
    info5 = five.step(jax.random.key(1), state, jnp.int32(0), params)[-1]
    info6 = six.step(jax.random.key(1), state, jnp.int32(0), params)[-1]
    assert "final_observation" not in info5 and info6["final_observation"].shape == six.observation_space().shape


def test_step_env_does_not_reset_and_has_five_values_in_both_apis(pair):
    """gymnax 1.x's step_env returns five values (obs, state, reward, terminated, info);
    under "done" the flag is done = terminated | truncated (gymnax 0.x's)."""
    five, six, params = pair
    _, state = five.reset(jax.random.key(0), params)
    for env in (five, six):
        out = env.step_env(jax.random.key(1), state, jnp.int32(5), params)  # Done: the episode ends
        assert len(out) == 5
        obs, new_state, _, flag, info = out
        assert int(new_state.time) == 1, "step_env must not reset"
        assert bool(flag) and bool(info["terminated"]) and not bool(info["truncated"])
        np.testing.assert_array_equal(obs, env.get_obs(new_state, params))


def test_step_env_agrees_with_step_where_no_reset_happens(pair):
    """A walk of 29 steps (no Done, below the 30-step limit): step and step_env return the
    same observation, state, reward and flag; on the 30th step_env truncates without a reset,
    its "done" flag set, its "terminated_truncated" flag (terminated) not."""
    five, six, params = pair
    _, start = five.reset(jax.random.key(0), params)
    for env in (five, six):
        state = start
        for t, action in enumerate([0, 1, 0, 2, 3, 4] * 5):
            key = jax.random.key(100 + t)
            obs_e, state_e, reward_e, flag_e, info_e = env.step_env(key, state, jnp.int32(action), params)
            if t == 29:
                assert int(state_e.time) == 30 and bool(info_e["truncated"]) and bool(env.is_truncated(state_e, params))
                assert bool(flag_e) == (env.step_api == "done")
                break
            obs, state, reward, *flags, _ = env.step(key, state, jnp.int32(action), params)
            np.testing.assert_array_equal(np.asarray(obs_e), np.asarray(obs))
            for a, b in zip(jax.tree.leaves(state_e), jax.tree.leaves(state)):
                np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
            assert float(reward_e) == float(reward) and not bool(flag_e) and not any(bool(f) for f in flags)


@pytest.mark.parametrize("gymnax_installed", [True, False], ids=["as_installed", "hidden"])
def test_the_gymnax_environment_members_give_gridnavs_values(pair, monkeypatch, gymnax_installed):
    """is_terminated and is_terminal (always False), discount (1), is_truncated (the room
    type's time limit), observe (the observation, whatever the key and action)
    and state_space (EnvState's fields) as gymnax 1.x's Environment has them, whatever is
    installed (with gymnax hidden the spaces are envs.spaces')."""
    if not gymnax_installed:
        monkeypatch.setattr(gymnax_compat, "installed_gymnax_version", lambda: None)
    five, six, params = pair
    _, state = five.reset(jax.random.key(0), params)
    limit = int(params.max_steps[int(state.room_type)])
    assert limit == 30
    for env in (five, six):
        for time, truncated in ((0, False), (limit - 1, False), (limit, True)):
            at = state.replace(time=jnp.int32(time))
            assert bool(env.is_truncated(at, params)) is truncated
            assert bool(env.is_terminated(at, params)) is bool(env.is_terminal(at, params)) is False
            assert float(env.discount(at, params)) == 1.0
        obs, _ = env.reset(jax.random.key(0), params)
        np.testing.assert_array_equal(env.observe(jax.random.key(5), state, jnp.int32(2), params), obs)
        np.testing.assert_array_equal(env.observe(jax.random.key(5), state, None, params), env.get_obs(state, params))
        # batched states work too, and under jit
        batch = jax.tree.map(lambda x: jnp.stack([x, x]), state.replace(time=jnp.int32(limit)))
        np.testing.assert_array_equal(np.asarray(jax.vmap(env.is_truncated, (0, None))(batch, params)), [True, True])
        assert float(jax.jit(env.discount)(state, params)) == 1.0
    space = five.state_space(params)
    assert list(space.spaces) == list(envs.EnvState.__dataclass_fields__)
    classes = own_spaces if not gymnax_installed else gymnax_compat._space_classes()
    assert type(space) is classes.Dict and type(space.spaces["heading"]) is classes.Discrete
    assert type(space.spaces["agent_pos"]) is classes.Box
    assert space.spaces["heading"].n == 8 and space.spaces["horizon"].n == 2 and space.spaces["room_type"].n == 4
    assert space.spaces["scene"].n == params.bank.numbers.shape[0]
    assert space.spaces["target"].n == five.gridnav.num_categories == 18
    assert space.spaces["target_slot"].n == params.bank.targets.shape[1]
    assert int(space.spaces["agent_pos"].high) == five.gridnav.grid_size - 1
    assert int(space.spaces["time"].high) == 30
    for key in range(8):
        _, reset = five.reset(jax.random.key(key), params)
        assert bool(space.contains(reset)), reset
        assert 1 <= int(reset.optimal_length) <= int(space.spaces["optimal_length"].high)
    assert not bool(space.contains(state.replace(agent_pos=jnp.array([0, five.gridnav.grid_size], jnp.int32))))
    assert not bool(space.contains(state.replace(time=jnp.int32(31))))


@needs_gymnax_1
def test_gymnax_1s_own_step_over_step_env_and_is_truncated_is_the_six_value_step(pair):
    """gymnax 1.x's Environment.step (step_env, then is_truncated, then its auto-reset) run
    on the env steps as its own six-value step does (no Done on a time limit's last step,
    where GridNav leaves truncated unset)."""
    from gymnax.environments.environment import Environment

    _, six, params = pair
    _, state = six.reset(jax.random.key(0), params)
    state_g = state
    for t, action in enumerate([0, 5] + [0, 1, 0, 2, 3, 4] * 6):
        key = jax.random.key(200 + t)
        ours = six.step(key, state, jnp.int32(action), params)
        theirs = Environment.step(six, key, state_g, jnp.int32(action), params)
        assert len(theirs) == 6
        for a, b in zip(jax.tree.leaves(ours[:5]), jax.tree.leaves(theirs[:5])):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        for name in ("terminated", "truncated", "final_observation", "success"):
            np.testing.assert_array_equal(np.asarray(ours[5][name]), np.asarray(theirs[5][name]))
        state, state_g = ours[1], theirs[1]


@pytest.mark.parametrize("gymnax_installed", [True, False], ids=["as_installed", "hidden"])
def test_without_step_api_the_step_has_five_values_whatever_is_installed(monkeypatch, gymnax_installed):
    if not gymnax_installed:
        monkeypatch.setattr(gymnax_compat, "installed_gymnax_version", lambda: None)
    with no_warning():
        env, params = envs.make_gymnax(room_types=ROOMS)
    assert env.step_api == "done" and not env.final_observation
    obs, state = env.reset(jax.random.key(0), params)
    out = env.step(jax.random.key(1), state, jnp.int32(0), params)
    assert len(out) == 5 and out[3].dtype == jnp.bool_ and "final_observation" not in out[4]
    assert len(env.step_env(jax.random.key(1), state, jnp.int32(0), params)) == 5


@pytest.mark.parametrize("version", [(1, 0, 1), (1, 1, 0), (0, 0, 9), None], ids=str)
def test_the_default_is_five_values_and_silent_whatever_gymnax_is_installed(monkeypatch, version):
    """No step_api: five values, no warning; "auto" follows the installed gymnax."""
    monkeypatch.setattr(gymnax_compat, "installed_gymnax_version", lambda: version)
    with no_warning():
        env, _ = envs.make_gymnax(room_types=ROOMS)
    assert env.step_api == "done"
    for step_api, expected in (
        ("done", "done"),
        ("terminated_truncated", "terminated_truncated"),
        ("auto", "terminated_truncated" if version and version >= (1,) else "done"),
    ):
        with no_warning():
            env, _ = envs.make_gymnax(room_types=ROOMS, step_api=step_api)
        assert env.step_api == expected and env.final_observation == (expected == "terminated_truncated")
    assert gymnax_compat.default_step_api() == "done"


def test_default_params_are_built_once(monkeypatch):
    from envs import gridnav

    calls = []
    real = gridnav.make_bank

    def first_scene_only(setup, numbers, *rest):  # counts the calls; the bank's size is not the question
        calls.append(tuple(numbers))
        return real(setup, tuple(numbers)[:1], *rest)

    monkeypatch.setattr(gridnav, "make_bank", first_scene_only)
    env, params = envs.make_gymnax(room_types=ROOMS, step_api="done")
    assert len(calls) == 1
    assert env.default_params is env.default_params is params
    grid = envs.GridNav()
    assert grid.default_params is grid.default_params
    assert len(calls) == 2
    assert calls[1] == tuple(C.scene_numbers("train", range(4)))  # the default: every room type of the train split
    # params=None takes the default params, as in gymnax
    obs, _ = env.reset(jax.random.key(0))
    np.testing.assert_array_equal(obs, env.reset(jax.random.key(0), params)[0])
    assert len(calls) == 2


def test_a_wrong_step_api_is_refused():
    with pytest.raises(ValueError, match="step_api must be one of"):
        envs.make_gymnax(step_api="four")


def test_without_gymnax_the_step_has_five_values_and_the_spaces_are_envs_own(monkeypatch):
    monkeypatch.setattr(gymnax_compat, "installed_gymnax_version", lambda: None)
    assert gymnax_compat.default_step_api() == gymnax_compat.installed_step_api() == "done"
    assert gymnax_compat.register_gymnax() is False
    with no_warning():
        env, params = envs.make_gymnax(room_types=ROOMS)
    assert env.step_api == "done" and not env.final_observation
    assert type(env.observation_space(params)) is own_spaces.Box
    assert type(env.action_space(params)) is own_spaces.Discrete


@needs_gymnax
def test_with_gymnax_the_spaces_are_gymnax_own():
    from gymnax.environments import spaces as gymnax_spaces

    with no_warning():
        env, params = envs.make_gymnax(room_types=ROOMS)
    assert isinstance(env.observation_space(params), gymnax_spaces.Box)
    assert isinstance(env.action_space(params), gymnax_spaces.Discrete)
    assert isinstance(env.state_space(params), gymnax_spaces.Dict)
    # the default is five values whatever is installed; "auto" is the installed gymnax's
    assert env.step_api == "done"
    auto, _ = envs.make_gymnax(room_types=ROOMS, step_api="auto")
    assert auto.step_api == ("terminated_truncated" if GYMNAX >= (1,) else "done")


@needs_gymnax_1
def test_gymnax_make_builds_it_with_keywords_once_registered():
    import gymnax

    assert envs.register_gymnax() and envs.register_gymnax()  # a second call is harmless
    env, params = gymnax.make("GridNav-v0", room_types=ROOMS, step_api="done", setup="org")
    assert isinstance(env, gymnax_compat.GymnaxGridNav) and env.step_api == "done"
    assert env.gridnav.setup == "org" and params is env.default_params
    assert "GridNav-v0" in gymnax.registered_envs
    # the same defaults as make_gymnax: five values unless step_api is passed, and no warning
    with no_warning():
        env, params = gymnax.make("GridNav-v0", room_types=ROOMS)
    assert env.step_api == "done" and not env.final_observation
    _, state = env.reset(jax.random.key(0), params)
    assert len(env.step(jax.random.key(1), state, jnp.int32(0), params)) == 5
    env, params = gymnax.make("GridNav-v0", room_types=ROOMS, step_api="terminated_truncated")
    assert env.step_api == "terminated_truncated" and env.final_observation
    assert len(env.step(jax.random.key(1), state, jnp.int32(0), params)) == 6


@needs_gymnax_1
def test_importing_envs_after_gymnax_registers_it():
    """gymnax.make without step_api: the five-value env, and nothing on stderr."""
    code = (
        "import gymnax, envs; env, p = gymnax.make('GridNav-v0', room_types=('bathroom',)); "
        "print(type(env).__name__, env.step_api)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["GymnaxGridNav", "done"]
    assert "FutureWarning" not in out.stderr and "step_api" not in out.stderr, out.stderr


def test_an_installed_gymnax_that_cannot_be_imported_is_one_clear_line(monkeypatch):
    """gymnax 1.0.1 imports `six` without declaring it; without six, the error says so."""

    def broken(name, *args, **kwargs):
        raise ModuleNotFoundError("No module named 'six'")

    monkeypatch.setattr(gymnax_compat, "installed_gymnax_version", lambda: (1, 0, 1))
    monkeypatch.setattr(gymnax_compat.importlib, "import_module", broken)
    env, params = envs.make_gymnax(room_types=ROOMS, step_api="done")
    with pytest.raises(ImportError, match=r"gymnax 1\.0\.1 is installed but cannot be imported .*pip install six"):
        env.observation_space(params)
    with pytest.raises(ImportError, match="pip install six"):
        envs.register_gymnax()


# ------------------------------------------------------------- what gymnax clients do with the objects
def test_env_and_params_survive_deepcopy_and_pickle_and_step_the_same():
    """rejax deep-copies its config (the env inside it); others pickle an env to send it to a
    worker. The copies step exactly as the original."""
    import copy
    import pickle

    env, params = envs.make_gymnax(room_types=ROOMS, step_api="done")
    key, action = jax.random.key(3), jnp.int32(0)
    obs, state = env.reset(key, params)
    expected = env.step(key, state, action, params)
    for copied_env, copied_params in [
        (copy.deepcopy(env), copy.deepcopy(params)),
        (pickle.loads(pickle.dumps(env)), pickle.loads(pickle.dumps(params))),
    ]:
        assert isinstance(copied_env, gymnax_compat.GymnaxGridNav) and copied_env.step_api == "done"
        obs2, state2 = copied_env.reset(key, copied_params)
        np.testing.assert_array_equal(np.asarray(obs2), np.asarray(obs))
        got = copied_env.step(key, state2, action, copied_params)
        for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(expected)):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    # deepcopy shares the immutable params (and so their scene bank) instead of copying them
    assert copy.deepcopy(params) is params and copy.deepcopy(env).default_params is params


def test_params_carry_gymnaxs_max_steps_in_episode_as_a_static_int():
    train_env, train_params = envs.make_gymnax(room_types=ROOMS, step_api="done")
    _, eval_params = envs.make_gymnax(room_types=ROOMS, split="test", training=False, step_api="done")
    assert train_params.max_steps_in_episode == 30 and type(train_params.max_steps_in_episode) is int
    assert eval_params.max_steps_in_episode == int(np.max(np.asarray(eval_params.max_steps))) == 200
    # static: a Python int inside jit, as a loop bound needs (rejax's evaluator)
    bound = jax.jit(lambda p: jnp.zeros(p.max_steps_in_episode))(train_params)
    assert bound.shape == (30,)
    # and the params are still GridNav's: the env steps with them unchanged
    assert isinstance(train_params, envs.EnvParams)


def test_params_hash_by_identity_so_they_can_be_a_static_jit_argument():
    env, params = envs.make_gymnax(room_types=ROOMS, step_api="done")
    assert hash(params) == hash(params) and params == params
    other = gymnax_compat.GymnaxEnvParams.of(env.gridnav.make_params("train", room_types=ROOMS))
    assert params != other  # equal contents, another object: another static key
    traces = []

    def first_obs(key, p):
        traces.append(1)
        return env.reset(key, p)[0]

    jitted = jax.jit(first_obs, static_argnums=1)
    a = jitted(jax.random.key(0), params)
    b = jitted(jax.random.key(0), params)
    assert len(traces) == 1  # the same params object finds its compiled program
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    np.testing.assert_array_equal(np.asarray(a), np.asarray(env.reset(jax.random.key(0), params)[0]))
