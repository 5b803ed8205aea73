"""GridNav dynamics: invariants under random rollouts, rewards, time limits, auto-reset,
and the jit / vmap / determinism contract of ``step``.

Expected values come from code written in the tests from the spec (``env_reference``)
or from a fresh ray cast of the bank's layout; the environment's own tables only choose
inputs (such as goal poses to call Done from).
"""

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import envs
from envs import catalog as C
from env_helpers import index_tree, make_states, random_states, states_target_visible, to_numpy
from env_reference import SPEC_DELTAS, reference_transition

ROLLOUT_STEPS = 24
UNREACHABLE = np.iinfo(np.int16).max
HYPOTHESIS = settings(
    max_examples=25,
    deadline=None,
    derandomize=True,
    print_blob=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


def make_rollout(env):
    """jit(rollout)(key, state, actions [T], use_oracle [T], params) -> per-step records.

    At each step the action is the oracle's where ``use_oracle`` else ``actions``; the
    record holds the state before the step, the action, ``step_env``'s result (no reset)
    and ``step``'s result (with auto-reset).
    """

    def rollout(key, state, actions, use_oracle, params):
        def body(carry, xs):
            state, key = carry
            action_random, use = xs
            key, k = jax.random.split(key)
            action = jnp.where(use, env.optimal_action(state, params), action_random)
            obs_env, state_env, *_ = env.step_env(k, state, action, params)
            obs, next_state, reward, terminated, truncated, info = env.step(k, state, action, params)
            record = dict(
                state=state,
                action=action,
                obs_env=obs_env,
                state_env=state_env,
                obs=obs,
                next_state=next_state,
                reward=reward,
                terminated=terminated,
                truncated=truncated,
                info=info,
            )
            return (next_state, key), record

        _, records = jax.lax.scan(body, (state, key), (actions, use_oracle))
        return records

    return jax.jit(rollout)


@pytest.fixture(scope="module")
def rollout(savn_kit):
    return make_rollout(savn_kit.env)


def check_fresh_episodes(kit, states, obs):
    """States right after a reset (batched, leading axis N): time 0, horizon 0, free start,
    a target present in the scene, not solved (fresh ray cast), optimal_length ==
    env.shortest_path_length, > 1 and finite, and obs == get_obs(state)."""
    bank = kit.bank
    s = to_numpy(states)
    n = s.scene.shape[0]
    np.testing.assert_array_equal(s.time, 0)
    np.testing.assert_array_equal(s.horizon, 0)
    assert ((0 <= s.heading) & (s.heading < 8)).all()
    np.testing.assert_array_equal(bank["cell_type"][s.scene, s.agent_pos[:, 0], s.agent_pos[:, 1]], C.CELL_FLOOR)
    np.testing.assert_array_equal(s.room_type, [C.room_type_of(int(bank["numbers"][i])) for i in s.scene])
    np.testing.assert_array_equal(bank["targets"][s.scene, s.target_slot], s.target)
    for i in range(n):
        cats = bank["obj_cat"][s.scene[i]]
        assert s.target[i] in set(cats[cats >= 0].tolist())
        state_i = index_tree(states, i)
        assert s.optimal_length[i] == int(kit.shortest_path_length(state_i, kit.params))
        chex.assert_trees_all_equal(index_tree(obs, i), kit.get_obs(state_i, kit.params))
    assert ((1 < s.optimal_length) & (s.optimal_length < UNREACHABLE)).all()
    assert not states_target_visible(kit, s).any(), "an episode starts already solved"


@given(
    seed=st.integers(0, 2**31 - 1),
    steps_before_limit=st.integers(0, 150),
    actions=st.lists(st.integers(0, 5), min_size=ROLLOUT_STEPS, max_size=ROLLOUT_STEPS),
    use_oracle=st.lists(st.booleans(), min_size=ROLLOUT_STEPS, max_size=ROLLOUT_STEPS),
)
@HYPOTHESIS
def test_random_rollouts_follow_the_spec(savn_kit, rollout, seed, steps_before_limit, actions, use_oracle):
    """Random scene, target, pose, time and action sequence (oracle actions mixed in so
    that Done succeeds sometimes); every step is checked against the reference dynamics,
    a fresh ray cast for success, the reward and time-limit rules, and auto-reset."""
    params, bank = savn_kit.params, savn_kit.bank
    rng = np.random.default_rng(seed)
    state = random_states(bank, rng, 1)
    limits = np.asarray(params.max_steps)
    time = max(int(limits[int(state.room_type[0])]) - 1 - steps_before_limit, 0)
    state = index_tree(state.replace(time=jnp.full((1,), time, jnp.int32)), 0)
    key = jax.random.key(seed)
    rec = to_numpy(rollout(key, state, jnp.asarray(actions, jnp.int32), jnp.asarray(use_oracle), params))

    s, s_env = rec["state"], rec["state_env"]
    visible = states_target_visible(savn_kit, s)
    for t in range(ROLLOUT_STEPS):
        a = int(rec["action"][t])
        cells = bank["cell_type"][int(s.scene[t])]
        pose = (int(s.agent_pos[t, 0]), int(s.agent_pos[t, 1]), int(s.heading[t]), int(s.horizon[t]))
        new = (int(s_env.agent_pos[t, 0]), int(s_env.agent_pos[t, 1]), int(s_env.heading[t]), int(s_env.horizon[t]))
        where = f"step {t}: pose {pose} action {C.ACTIONS[a]} -> {new}"
        # Stays in bounds, never inside a wall, furniture or floor object.
        assert 0 <= new[0] < cells.shape[0] and 0 <= new[1] < cells.shape[1], where
        assert cells[new[0], new[1]] == C.CELL_FLOOR, where
        # A diagonal MoveAhead never cuts a blocked corner.
        if new[:2] != pose[:2]:
            dr, dc = new[0] - pose[0], new[1] - pose[1]
            assert a == C.MOVE_AHEAD and (dr, dc) == SPEC_DELTAS[pose[2]], where
            assert cells[pose[0] + dr, pose[1]] == C.CELL_FLOOR and cells[pose[0], pose[1] + dc] == C.CELL_FLOOR, where
        # Headings 0..7, horizons {0, 1}; rotations -1/+1 mod 8; looks clamp.
        assert 0 <= new[2] < 8 and new[3] in (0, 1), where
        if a == C.ROTATE_LEFT:
            assert new[2] == (pose[2] - 1) % 8, where
        if a == C.ROTATE_RIGHT:
            assert new[2] == (pose[2] + 1) % 8, where
        if a == C.LOOK_UP:
            assert new[3] == max(pose[3] - 1, 0), where
        if a == C.LOOK_DOWN:
            assert new[3] == min(pose[3] + 1, 1), where
        # The whole transition equals the reference.
        assert new == reference_transition(cells, pose, a), where
        assert s_env.time[t] == s.time[t] + 1
        # Done always ends the episode; success exactly when the target is in view and range.
        assert rec["terminated"][t] == (a == C.DONE), where
        success = (a == C.DONE) and bool(visible[t])
        assert rec["info"]["success"][t] == success, where
        assert rec["reward"][t] == (np.float32(5.0) if success else np.float32(-0.01)), where
        # The time limit truncates (and does not terminate).
        limit = 200 if s.room_type[t] == C.LIVING_ROOM else 100
        assert rec["truncated"][t] == ((a != C.DONE) and s.time[t] + 1 >= limit), where
        assert rec["info"]["episode_length"][t] == s.time[t] + 1
        assert rec["info"]["optimal_length"][t] == s.optimal_length[t]
        # final_observation is the observation of the step just taken; auto-reset on done.
        chex.assert_trees_all_equal(index_tree(rec["info"]["final_observation"], t), index_tree(rec["obs_env"], t))
        if not (rec["terminated"][t] or rec["truncated"][t]):
            chex.assert_trees_all_equal(index_tree(rec["next_state"], t), index_tree(s_env, t))
            chex.assert_trees_all_equal(index_tree(rec["obs"], t), index_tree(rec["obs_env"], t))
    event(f"successes: {int(rec['info']['success'].sum() > 0)}, truncations: {int(rec['truncated'].sum() > 0)}")
    ended = np.flatnonzero(rec["terminated"] | rec["truncated"])
    if len(ended):
        fresh = jax.tree.map(lambda x: jnp.asarray(x[ended]), rec["next_state"])
        check_fresh_episodes(savn_kit, fresh, jax.tree.map(lambda x: x[ended], rec["obs"]))


def test_done_success_and_reward_match_a_fresh_ray_cast(savn_kit):
    """Done at random poses and at goal poses: success and reward are exactly 'a target
    pixel with depth <= 4 cells' of a fresh ray cast; Done always terminates."""
    bank = savn_kit.bank
    rng = np.random.default_rng(1)
    states = random_states(bank, rng, 128)
    # Move half of them onto goal poses (free cells with bank distance 1).
    grid = bank["cell_type"].shape[1]
    goal = []
    for i in range(64):
        s, k = int(states.scene[i]), int(states.target_slot[i])
        free = np.repeat((bank["cell_type"][s] == C.CELL_FLOOR).reshape(-1), 16)
        goal.append((s, k, int(rng.choice(np.flatnonzero((bank["distance"][s, k] == 1) & free)))))
    g = np.array(goal)
    cell = g[:, 2] // 16
    goal_pos = np.stack([cell // grid, cell % grid], -1)
    goal_states = make_states(bank, g[:, 0], g[:, 1], goal_pos, g[:, 2] // 2 % 8, g[:, 2] % 2)
    states = jax.tree.map(lambda a, b: jnp.concatenate([a[:64], b]), states, goal_states)
    keys = jax.random.split(jax.random.key(0), 128)
    _, _, reward, terminated, truncated, info = savn_kit.step_batch(keys, states, np.full(128, C.DONE))
    visible = states_target_visible(savn_kit, states)
    assert visible[64:].all(), "the oracle's goal poses must show the target within the radius"
    assert 0 < visible.sum() < 128
    np.testing.assert_array_equal(info["success"], visible)
    np.testing.assert_array_equal(reward, np.where(visible, np.float32(5.0), np.float32(-0.01)))
    assert terminated.all() and not truncated.any()


def test_time_limits_of_the_splits(savn_train_narrow, savn_val_narrow, savn_test):
    """Training limit 30 on the train split; 100 (200 in living rooms) on val and test."""
    for (_, params), expected in (
        (savn_train_narrow, [30, 30, 30, 30]),
        (savn_val_narrow, [100, 200, 100, 100]),
        (savn_test, [100, 200, 100, 100]),
    ):
        np.testing.assert_array_equal(np.asarray(params.max_steps), expected)
        assert params.max_steps.dtype == jnp.int32
    np.testing.assert_array_equal(envs.time_limits(True), [30, 30, 30, 30])
    np.testing.assert_array_equal(envs.time_limits(False), [100, 200, 100, 100])


@pytest.mark.parametrize("training", [False, True])
def test_time_limit_truncates_and_does_not_terminate(savn_kit, training):
    """An agent that only rotates is truncated exactly at the limit of its room type
    (30 in training, 100 / 200 in evaluation), never terminated, then auto-reset."""
    env = savn_kit.env
    params = env.make_params("test", training=training)  # same shapes: the compiled step is reused
    limits = [30] * 4 if training else [100, 200, 100, 100]
    n = 64
    obs, states = savn_kit.reset_batch(jax.random.split(jax.random.key(3), n))
    rooms = np.asarray(states.room_type)
    assert set(rooms.tolist()) == {0, 1, 2, 3}
    key = jax.random.key(4)
    truncated_at = np.full(n, -1)
    for t in range(max(limits) + 1):
        key, k = jax.random.split(key)
        times = np.asarray(states.time)
        obs, states, _, terminated, truncated, _ = savn_kit._step_batch(
            jax.random.split(k, n), states, jnp.full((n,), C.ROTATE_LEFT, jnp.int32), params
        )
        assert not np.asarray(terminated).any()
        truncated = np.asarray(truncated)
        first = truncated & (truncated_at < 0)
        np.testing.assert_array_equal(times[truncated_at < 0], t)  # time counts steps
        truncated_at[first] = t
        np.testing.assert_array_equal(np.asarray(states.time)[first], 0)  # auto-reset
    np.testing.assert_array_equal(truncated_at + 1, np.asarray(limits)[rooms])


def test_auto_reset_after_done_gives_fresh_valid_episodes(savn_kit):
    """Done from random states: each next state is a fresh, valid, unsolved episode and
    final_observation is step_env's observation of the last real step."""
    states = random_states(savn_kit.bank, np.random.default_rng(2), 64, time=np.full(64, 7))
    keys = jax.random.split(jax.random.key(5), 64)
    done = np.full(64, C.DONE)
    obs, next_states, _, terminated, _, info = savn_kit.step_batch(keys, states, done)
    obs_env, state_env, *_ = savn_kit.step_env_batch(keys, states, done)
    assert terminated.all()
    np.testing.assert_array_equal(state_env.time, 8)
    chex.assert_trees_all_equal(info["final_observation"], obs_env)
    check_fresh_episodes(savn_kit, jax.tree.map(jnp.asarray, next_states), obs)
    assert len(set(next_states.scene.tolist())) > 5, "resets should spread over the scenes of the split"


def test_reset_is_fresh_and_spreads_over_targets(savn_kit):
    obs, states = savn_kit.reset_batch(jax.random.split(jax.random.key(9), 256))
    every_fourth = lambda tree: jax.tree.map(lambda x: jnp.asarray(x[::4]), tree)
    check_fresh_episodes(savn_kit, every_fourth(states), every_fourth(obs))
    assert len(set(zip(states.scene.tolist(), states.target.tolist()))) > 40
    assert set(states.heading.tolist()) == set(range(8))
    assert set(states.room_type.tolist()) == {0, 1, 2, 3}


# ----------------------------------------------------------------------- jit / vmap / keys
class StepContractTest(chex.TestCase):
    """step is the same with and without jit, under vmap, and for the same key."""

    @pytest.fixture(autouse=True)
    def _kit(self, savn_kit):
        self.kit = savn_kit
        self.env, self.params = savn_kit.env, savn_kit.params

    @chex.variants(with_jit=True, without_jit=True)
    def test_step_matches_reference_and_jitted_step(self):
        """Each action from a random state: identical (bitwise) to the jitted step, and the
        pose / reward / flags the reference dynamics expect."""
        env, params, bank = self.env, self.params, self.kit.bank
        states = random_states(bank, np.random.default_rng(4), 6)
        step = self.variant(env.step)
        for action in range(C.NUM_ACTIONS):
            state = index_tree(states, action)
            key = jax.random.key(action)
            out = step(key, state, jnp.int32(action), params)
            chex.assert_trees_all_equal(out, self.kit.step(key, state, jnp.int32(action), params))
            obs, next_state, reward, terminated, truncated, info = out
            s = to_numpy(state)
            cells = bank["cell_type"][int(s.scene)]
            pose = (int(s.agent_pos[0]), int(s.agent_pos[1]), int(s.heading), int(s.horizon))
            if action != C.DONE:
                n = to_numpy(next_state)
                assert (int(n.agent_pos[0]), int(n.agent_pos[1]), int(n.heading), int(n.horizon)) == (
                    reference_transition(cells, pose, action)
                )
                assert reward == np.float32(-0.01) and not terminated and not truncated
            else:
                assert terminated and int(next_state.time) == 0
            chex.assert_shape(obs["view"], (3, env.view_width, env.num_semantic + 1))
            chex.assert_type([reward, terminated, truncated], [jnp.float32, bool, bool])

    def test_vmap_equals_python_loop(self):
        n = 64
        states = random_states(self.kit.bank, np.random.default_rng(5), n)
        actions = jnp.asarray(np.arange(n) % C.NUM_ACTIONS, jnp.int32)
        keys = jax.random.split(jax.random.key(11), n)
        batched = self.kit._step_batch(keys, states, actions, self.params)
        looped = [self.kit.step(keys[i], index_tree(states, i), actions[i], self.params) for i in range(n)]
        chex.assert_trees_all_equal(batched, jax.tree.map(lambda *xs: jnp.stack(xs), *looped))

    def test_jitted_step_traces_once(self):
        chex.clear_trace_counter()
        step = jax.jit(chex.assert_max_traces(self.env.step, n=1))
        obs, state = self.kit.reset_batch(jax.random.split(jax.random.key(0), 1))
        state = jax.tree.map(lambda x: jnp.asarray(x[0]), state)
        key = jax.random.key(1)
        for i in range(40):  # crosses episode boundaries (Done every 6th step)
            key, k = jax.random.split(key)
            obs, state, reward, terminated, truncated, info = step(k, state, jnp.int32(i % C.NUM_ACTIONS), self.params)
        jax.block_until_ready(state)

    def test_same_key_same_trajectory_bitwise(self):
        """Two runs of a batch of 64-step random trajectories (actions drawn from the key)
        are bitwise equal; another key gives another trajectory."""
        kit = self.kit

        def run(key, steps=64):
            k_reset, key = jax.random.split(key)
            obs, states = kit.reset_batch(jax.random.split(k_reset, 64))
            out = []
            for _ in range(steps):
                key, k_act, k_step = jax.random.split(key, 3)
                actions = jax.random.randint(k_act, (64,), 0, C.NUM_ACTIONS)
                step_out = kit._step_batch(jax.random.split(k_step, 64), states, actions, self.params)
                states = step_out[1]
                out.append((actions, step_out))
            return out

        first, second = run(jax.random.key(21)), run(jax.random.key(21))
        chex.assert_trees_all_equal(first, second)
        other = run(jax.random.key(22), steps=1)
        assert not np.array_equal(np.asarray(first[0][1][1].agent_pos), np.asarray(other[0][1][1].agent_pos))
