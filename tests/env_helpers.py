"""Small helpers shared by the environment tests (not tests themselves)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from envs import catalog as C
from envs import raycast
from envs.gridnav import EnvState
from env_reference import bfs_distances, pose_graph


BATCH = 64  # every batched jitted call is padded to a multiple of this (one compile each)
CAST_CHUNK = 1024  # ray casts of many poses run in chunks of this size
EPISODE_STEPS = 80  # Kit.first_episodes: longer than any optimal path; (5/6)^80 < 1e-6 for random


@functools.partial(jax.jit, static_argnames="view_width")
def _cast_views(cell_type, obj_cat, obj_band, pos, heading, horizon, view_width: int):
    cast = lambda ct, oc, ob, p, h, z: raycast.cast_view(ct, oc, ob, p, h, z, view_width)
    return jax.vmap(cast)(cell_type, obj_cat, obj_band, pos, heading, horizon)


def pad_to_batch(tree, multiple=BATCH):
    """Pad the leading axis of every leaf to a multiple of ``multiple`` (repeating row 0)."""
    n = jax.tree.leaves(tree)[0].shape[0]
    extra = -n % multiple
    return jax.tree.map(lambda x: np.concatenate([np.asarray(x), np.repeat(np.asarray(x)[:1], extra, 0)]), tree)


def cast_views(cell_type, obj_cat, obj_band, pos, heading, horizon, view_width: int):
    """raycast.cast_view (jitted) vmapped over a leading axis N of every argument.

    cell_type, obj_cat, obj_band: [N, G, G]; pos: [N, 2]; heading, horizon: [N].
    Returns numpy sem int32 [N, 3, W], depth float32 [N, 3, W].
    """
    args = [np.asarray(a) for a in (cell_type, obj_cat, obj_band)]
    args += [np.asarray(pos, np.int32), np.asarray(heading, np.int32), np.asarray(horizon, np.int32)]
    n = args[0].shape[0]
    chunk = CAST_CHUNK if n > BATCH else BATCH
    padded = pad_to_batch(args, chunk)
    outs = [
        _cast_views(*(a[i : i + chunk] for a in padded), view_width=view_width) for i in range(0, len(padded[0]), chunk)
    ]
    sem = np.concatenate([np.asarray(o[0]) for o in outs])[:n]
    depth = np.concatenate([np.asarray(o[1]) for o in outs])[:n]
    return sem, depth


def bank_numpy(params):
    """The scene bank of ``params`` as numpy arrays (a dict)."""
    return {k: np.asarray(v) for k, v in vars(params.bank).items()}


def target_visible(bank_np, scene, pos, heading, horizon, target, radius_m, view_width):
    """bool [N]: a pixel of the target category with depth <= radius (cells), computed
    from a fresh ray cast of the bank's layout (not from the bank's tables)."""
    scene = np.asarray(scene)
    sem, depth = cast_views(
        bank_np["cell_type"][scene],
        bank_np["obj_cat"][scene],
        bank_np["obj_band"][scene],
        pos,
        heading,
        horizon,
        view_width=view_width,
    )
    target = np.asarray(target)[:, None, None]
    return ((sem == C.NUM_STRUCTURAL + target) & (depth <= radius_m / C.CELL_SIZE_M)).any((1, 2))


def states_target_visible(kit, states):
    """target_visible for a batch of (numpy or jax) EnvStates of kit's env."""
    s, env = to_numpy(states), kit.env
    pose = (s.agent_pos, s.heading, s.horizon)
    return target_visible(kit.bank, s.scene, *pose, s.target, env.success_radius_m, env.view_width)


def random_states(bank_np, rng, n, time=None):
    """A batch of n valid EnvStates at random scenes, targets and free-cell poses.

    time: int [n] or None (zeros).  optimal_length is set to the bank's distance of the
    pose (it is only reported in ``info``).
    """
    num_scenes, grid_size = bank_np["cell_type"].shape[:2]
    scene = rng.integers(0, num_scenes, n)
    slot = (rng.random(n) * bank_np["num_targets"][scene]).astype(np.int64)
    pos = np.zeros((n, 2), np.int64)
    for i, s in enumerate(scene):
        free = np.argwhere(bank_np["cell_type"][s] == C.CELL_FLOOR)
        pos[i] = free[rng.integers(len(free))]
    heading = rng.integers(0, C.NUM_HEADINGS, n)
    horizon = rng.integers(0, C.NUM_HORIZONS, n)
    return make_states(bank_np, scene, slot, pos, heading, horizon, time)


def make_states(bank_np, scene, slot, pos, heading, horizon, time=None):
    """A batch of EnvStates from numpy arrays of poses (leading axis N)."""
    grid_size = bank_np["cell_type"].shape[1]
    scene, slot, pos = np.asarray(scene), np.asarray(slot), np.asarray(pos)
    heading, horizon = np.asarray(heading), np.asarray(horizon)
    n = scene.shape[0]
    time = np.zeros(n, np.int64) if time is None else np.asarray(time)
    pose = ((pos[:, 0] * grid_size + pos[:, 1]) * 8 + heading) * 2 + horizon
    i32 = lambda x: jnp.asarray(x, jnp.int32)
    return EnvState(
        agent_pos=i32(pos),
        heading=i32(heading),
        horizon=i32(horizon),
        scene=i32(scene),
        room_type=i32(bank_np["room_types"][scene, bank_np["target_room"][scene, slot]]),
        target=i32(bank_np["targets"][scene, slot]),
        target_slot=i32(slot),
        time=i32(time),
        optimal_length=i32(bank_np["distance"][scene, slot, pose]),
    )


def index_tree(tree, i):
    """Element i of a batched pytree."""
    return jax.tree.map(lambda x: x[i], tree)


def to_numpy(tree):
    return jax.tree.map(np.asarray, tree)


# The oracle by the reference BFS (tests/envs/test_oracle.py; the goal view and houses use it too).
UNREACHABLE = np.iinfo(np.int16).max


def reference_oracle(kit, scene):
    """For one bank scene: ({slot: {pose: distance}}, free poses [N, 4]) by the reference BFS,
    with goal poses from a fresh ray cast (target pixel with depth <= radius)."""
    bank = kit.bank
    cell_type = bank["cell_type"][scene]
    free = np.argwhere(cell_type == C.CELL_FLOOR)
    poses = np.array([(r, c, h, z) for r, c in free for h in range(8) for z in range(2)])
    n = len(poses)
    grids = [np.broadcast_to(bank[k][scene], (n,) + cell_type.shape) for k in ("cell_type", "obj_cat", "obj_band")]
    sem, depth = cast_views(*grids, poses[:, :2], poses[:, 2], poses[:, 3], view_width=kit.env.view_width)
    in_range = depth <= kit.env.success_radius_m / C.CELL_SIZE_M
    parents = pose_graph(cell_type)
    out = {}
    for slot in range(int(bank["num_targets"][scene])):
        cat = int(bank["targets"][scene, slot])
        seen = ((sem == C.NUM_STRUCTURAL + cat) & in_range).any((1, 2))
        goal = {tuple(int(v) for v in p) for p in poses[seen]}
        out[slot] = bfs_distances(cell_type, goal, parents), goal
    return out, poses


_ORACLES = {}


def oracle_key(kit, scene):
    return kit.env.setup, kit.env.layout, kit.env.priors, kit.env.view_width, int(kit.bank["numbers"][scene])


def cached_reference_oracle(kit, scene):
    """reference_oracle(kit, scene), computed once per session (keyed by the scene's own
    number, not its index in the kit's bank, and by the layout family, so that banks of other
    splits, layouts or of rooms with priors
    never share an entry)."""
    key = oracle_key(kit, scene)
    if key not in _ORACLES:
        _ORACLES[key] = reference_oracle(kit, scene)
    return _ORACLES[key]


def cached_oracle(kit, scene):
    """cached_reference_oracle(kit, scene)[0]: {slot: ({pose: distance}, goal poses)}."""
    return cached_reference_oracle(kit, scene)[0]


def bank_pose_index(poses, grid):
    return ((poses[:, 0] * grid + poses[:, 1]) * 8 + poses[:, 2]) * 2 + poses[:, 3]


class Kit:
    """An env, its params, the bank as numpy and jitted functions compiled once per session.

    Batched functions take a leading axis of BATCH (use ``batched``) so that they compile once.
    """

    def __init__(self, env, params, episode_steps: int = EPISODE_STEPS):
        self.env, self.params, self.episode_steps = env, params, episode_steps
        self.bank = bank_numpy(params)
        self.step = jax.jit(env.step)
        self.step_env = jax.jit(env.step_env)
        self.get_obs = jax.jit(env.get_obs)
        self.shortest_path_length = jax.jit(env.shortest_path_length)
        self.optimal_action = jax.jit(env.optimal_action)
        in_axes = (0, 0, 0, None)
        self._step_batch = jax.jit(jax.vmap(env.step, in_axes=in_axes))
        self._step_env_batch = jax.jit(jax.vmap(env.step_env, in_axes=in_axes))
        self._reset_batch = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))
        self._obs_batch = jax.jit(jax.vmap(env.get_obs, in_axes=(0, None)))

    def batched(self, fn, *args):
        """fn over args with a leading axis N, padded to a multiple of BATCH and run in chunks."""
        n = jax.tree.leaves(args)[0].shape[0]
        is_key = lambda a: isinstance(a, jax.Array) and jnp.issubdtype(a.dtype, jax.dtypes.prng_key)
        keys = [i for i, a in enumerate(args) if is_key(a)]
        padded = list(args)
        for i, a in enumerate(args):
            if i in keys:  # pad typed keys by splitting a fresh one
                extra = -n % BATCH
                padded[i] = jnp.concatenate([a, jax.random.split(jax.random.key(0), extra)]) if extra else a
            else:
                padded[i] = pad_to_batch(a)
        outs = []
        for start in range(0, n + (-n % BATCH), BATCH):
            chunk = [jax.tree.map(lambda x: x[start : start + BATCH], a) for a in padded]
            outs.append(fn(*chunk, self.params))
        return jax.tree.map(lambda *xs: np.concatenate([np.asarray(x) for x in xs])[:n], *outs)

    def first_episodes(self, keys, use_oracle):
        """Run the first episode of each lane (reset by its key) for ``episode_steps`` steps, acting
        with env.optimal_action where use_oracle [N] else uniformly at random.

        Returns numpy (success, length, optimal_length, still_running), each [N].  One
        compiled program per Kit (N must stay the same between calls).
        """
        if not hasattr(self, "_episodes"):
            env, params = self.env, self.params

            def episode(key, oracle):
                k_reset, key = jax.random.split(key)
                _, state = env.reset(k_reset, params)

                def body(carry, _):
                    state, alive, success, length, key = carry
                    key, k_act, k_step = jax.random.split(key, 3)
                    action = jnp.where(
                        oracle, env.optimal_action(state, params), jax.random.randint(k_act, (), 0, C.NUM_ACTIONS)
                    )
                    _, state, _, terminated, truncated, info = env.step(k_step, state, action, params)
                    success = success | (alive & info["success"])
                    length = jnp.where(alive, info["episode_length"], length)
                    return (state, alive & ~(terminated | truncated), success, length, key), None

                init = (state, jnp.array(True), jnp.array(False), jnp.array(0, jnp.int32), key)
                (_, alive, success, length, _), _ = jax.lax.scan(body, init, None, self.episode_steps)
                return success, length, state.optimal_length, alive

            self._episodes = jax.jit(jax.vmap(episode))
        return jax.tree.map(np.asarray, self._episodes(keys, jnp.asarray(use_oracle)))

    def step_batch(self, keys, states, actions):
        return self.batched(self._step_batch, keys, states, jnp.asarray(actions, jnp.int32))

    def step_env_batch(self, keys, states, actions):
        return self.batched(self._step_env_batch, keys, states, jnp.asarray(actions, jnp.int32))

    def reset_batch(self, keys):
        return self.batched(self._reset_batch, keys)

    def obs_batch(self, states):
        return self.batched(self._obs_batch, states)
