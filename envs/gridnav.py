"""GridNav-v0: object-target visual navigation on a grid, a jit-compiled stand-in for AI2-THOR.

The gymnax 1.0 contract: ``reset(key, params) -> (obs, state)`` and
``step(key, state, action, params) -> (obs, state, reward, terminated, truncated, info)``
with automatic reset inside ``step`` (by ``jnp.where``, not ``lax.cond``) and (unless
constructed with ``final_observation=False``) ``info["final_observation"]`` holding the
last real observation of an episode that ended.  Everything is a pure function of explicit
keys, states and params; vmap it for batches.  The full contract (observation, actions,
reward, termination, ``info`` keys) is in the docstring of ``GridNav``.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from envs import catalog as C
from envs import spaces
from envs.bank import UNREACHABLE, SceneBank, make_bank
from envs.dynamics import pose_index, transition
from envs.houses import house_room_types
from envs.raycast import DEPTH_RESOLUTION, NUM_ROWS, cast_view

TRAIN_TIME_LIMIT = 30  # SAVN's training episode length
EVAL_TIME_LIMIT = 100
EVAL_TIME_LIMIT_LIVING_ROOM = 200
# Houses (layout="house"): the paths are about 3x a single room's (savn test split: median
# L^g 19 against 6, 95th percentile 46 against 19): the limits are scaled by 2x (training:
# longer than the shortest path of every training start, 99th percentile 48) and 3x (evaluation).
HOUSE_TRAIN_TIME_LIMIT = 60
HOUSE_EVAL_TIME_LIMIT = 300
GRID_SIZES = {"room": 20, "house": 30}  # the default grid_size of each layout
NUM_DETECTION_FEATURES = 7  # visible, col min/max, row min/max, confidence, is target


@struct.dataclass
class EnvState:
    agent_pos: jax.Array  # int32 [2] (row, col)
    heading: jax.Array  # int32 [] 0..7, 45 degree steps clockwise from north
    horizon: jax.Array  # int32 [] 0 = level, 1 = 30 degrees down
    scene: jax.Array  # int32 [] index into the scene bank
    room_type: jax.Array  # int32 [] catalog.KITCHEN ...: the type of the room holding the target
    target: jax.Array  # int32 [] category index in the setup's category list
    target_slot: jax.Array  # int32 [] index of the target in bank.targets[scene]
    time: jax.Array  # int32 [] steps taken in this episode
    optimal_length: jax.Array  # int32 [] shortest number of actions to success from the start


@struct.dataclass
class EnvParams:
    bank: SceneBank  # the scenes of the split, with their precomputed tables
    max_steps: jax.Array  # int32 [4] time limit by room type (kitchen, living, bed, bath)
    success_reward: float = 5.0
    step_penalty: float = -0.01
    # Reward per action of progress towards success, w (d_t - d_{t+1}) with d the oracle's
    # actions to success (a deviation from the paper's reward: AllenAct's ObjectNav
    # `shaping_weight`). Static: 0, the paper's reward, compiles without the two lookups.
    progress_reward: float = struct.field(pytree_node=False, default=0.0)


def time_limits(training: bool, layout: str = "room") -> jax.Array:
    """Episode limits by room type: 30 for training; 100 (200 in living rooms) for evaluation;
    in houses 60 and 300 whatever the room type."""
    C.check_layout(layout)
    if layout == "house":
        return jnp.full(4, HOUSE_TRAIN_TIME_LIMIT if training else HOUSE_EVAL_TIME_LIMIT, jnp.int32)
    if training:
        return jnp.full(4, TRAIN_TIME_LIMIT, jnp.int32)
    limits = [EVAL_TIME_LIMIT] * 4
    limits[C.LIVING_ROOM] = EVAL_TIME_LIMIT_LIVING_ROOM
    return jnp.asarray(limits, jnp.int32)


class GridNav:
    """The environment.  Shape-setting values are static constructor arguments.

    - Observation (a dict; ``observation_space`` gives shapes and bounds):
        - ``view``: float32 [3, W, n_semantic + 1], the first-person view (3 vertical
          bands x W rays over a 100 degree field of view): a one-hot of the semantic class
          of each pixel (nothing, wall, floor, furniture, then the setup's categories) and,
          last, its depth divided by ``max_depth`` (in (0, 1]).
        - ``target``: float32 [300] word vector (savn) or [22] one-hot (org) of the target
          category.
        - ``detections`` (org only): float32 [22, 7] per category: visible, column box
          (min, max), row box (min, max), confidence, is the target.
      ``envs.wrappers.FlattenObservationWrapper`` turns it into one float32 vector.
    - Actions: ``Discrete(6)``: 0 MoveAhead (blocked by walls, furniture and floor objects:
      the pose is unchanged), 1 RotateLeft, 2 RotateRight (45 degrees), 3 LookUp, 4 LookDown
      (camera horizon 0 or 30 degrees down), 5 Done.  An action must have an integer dtype
      (a float or bool action is a TypeError when ``step`` is traced: truncating 2.7 to 2
      would hide a bug).  An integer outside 0..5 matches no action: it is a step that
      leaves the pose unchanged and costs the step penalty, like a blocked MoveAhead (no
      check inside a jitted step is free); construct with ``check_actions=True`` to have
      such an action raise instead (a host callback per step: for debugging, not training).
    - Reward: ``params.success_reward`` (+5) on a successful Done (the target visible within
      the success radius), ``params.step_penalty`` (-0.01) on every other step; with
      ``params.progress_reward`` w > 0 (default 0, the paper's reward), every step adds
      w (d_t - d_{t+1}), d the oracle's shortest number of actions to success before and
      after it (AllenAct's ObjectNav reward shaping, by the exact oracle; over an episode it
      sums to w (L^g - d_end), so it cannot be farmed).
    - Termination: ``terminated`` when the agent takes Done (successful or not);
      ``truncated`` when the time limit of the room type (``params.max_steps``) is reached
      without Done.  ``step`` resets automatically when either is set: the returned
      observation and state are then those of the next episode.
    - ``info`` (about the step just taken, so about the episode that was being stepped even
      when ``step`` has just reset to a new one):
        - ``success`` bool: the Done succeeded.
        - ``episode_length`` int32: steps taken in the episode, this one included.
        - ``optimal_length`` int32: the oracle's shortest number of actions to success from
          the episode's start (Done counted), SPL's L^g.
        - ``room_type`` int32 (catalog.KITCHEN ...), ``scene`` int32 (AI2-THOR number),
          ``target`` int32 (category index in the setup's list).
        - ``terminated``, ``truncated`` bool: the two flags again (kept by wrappers that
          merge them into ``done``).
        - ``final_observation``: the observation reached by this step, before any automatic
          reset (the last real observation of an episode that ended).  Only when
          ``final_observation=True`` (the default).  It is a whole observation per step
          (about 5.6 KB: 1404 float32 in savn with W = 16), which loops that keep ``info``
          as per-step metrics pay for in memory; pass ``final_observation=False`` when
          nothing reads it (under jit XLA drops it anyway when it is neither used
          nor returned).
      Agents should read per-episode facts (optimal length, room type, scene, target) from
      ``info``, not from ``EnvState`` fields: after an automatic reset the returned state
      already belongs to the next episode, and ``EnvState``'s layout is not part of the API.

    Args:
      setup: "savn" (18 categories, 1.0 m, 300-d word-vector targets) or "org"
        (22 categories, 1.5 m, one-hot targets, detector features in the observation).
      layout: "room" (single AI2-THOR-like rooms, the default) or "house" (houses of 2-4
        rooms joined by doorways, envs.houses: longer paths, the target mostly in another
        room at the start, time limits 60 / 300).  In a house, ``room_types`` (of
        ``make_params``) selects the targets by the type of the room that holds them,
        and ``info["room_type"]`` is that room's type.
      priors: layouts with the regularities of real homes (envs.priors): furniture of
        distinct kinds, each its own semantic class in the view (after the categories), every
        target placed by relations to furniture and other targets, houses' rooms in adjacent
        pairs, and (savn) target word vectors related as the categories are.  False (the
        default) gives today's layouts, whose targets stand uniformly at random.
      perception_range: None (the default: every object pixel shows its category, at any
        depth) or a range in cells (0.25 m): an object pixel deeper than it shows one more
        class, ``unresolved_class`` (the last: "an object, not resolved"), in ``view``, in
        the observation and in org's detections; walls, floor and furniture show as
        without it. A far target is then seen as some object, its anchor furniture as what
        it is (docs/foresight.md, "Levers"). The layouts, banks, oracle and success are
        unchanged.
      grid_size: side of the padded scene grid, in 0.25 m cells (default 20 for rooms,
        30 for houses).
      view_width: number of view columns (rays) across the 100 degree field of view.
      precomputed_views: gather each pose's view from the scene bank's table (fast) or
        ray cast it at every step (same pixels; for checking and benchmarking).
      final_observation: whether ``step`` puts ``final_observation`` in ``info`` (see above).
      check_actions: raise on an action outside 0..5 (see above; slower, for debugging).
    """

    def __init__(
        self,
        setup: str = "savn",
        grid_size: int | None = None,
        view_width: int = 16,
        precomputed_views: bool = True,
        final_observation: bool = True,
        check_actions: bool = False,
        layout: str = "room",
        priors: bool = False,
        perception_range: float | None = None,
    ):
        C.check_setup(setup)
        C.check_layout(layout)
        self.layout = layout
        grid_size = GRID_SIZES[layout] if grid_size is None else int(grid_size)
        if view_width < 1:
            raise ValueError(f"view_width must be positive, got {view_width}")
        self.setup = setup
        self.grid_size = grid_size
        self.view_width = view_width
        self.precomputed_views = precomputed_views
        self.final_observation = bool(final_observation)
        self.check_actions = bool(check_actions)
        self.categories = C.categories(setup)
        self.num_categories = len(self.categories)
        self.success_radius_m = C.SETUPS[setup][2]
        self.priors = bool(priors)
        self.perception_range = check_perception_range(perception_range)
        # With a perception range, one more class after the others: an object seen but not resolved.
        self.unresolved_class = C.num_semantic(setup, self.priors)
        self.num_semantic = self.unresolved_class + (self.perception_range is not None)
        self.max_depth = float(grid_size) * 1.5  # depth channel = depth in cells / max_depth
        # Multiply by reciprocals, never divide by constants: XLA rewrites x / c as
        # x * (1 / c) under jit only, which would make jit and no-jit differ in the last bit.
        self._inv_max_depth = jnp.float32(1.0 / self.max_depth)

    # ----------------------------------------------------------------- gymnax API
    @property
    def name(self) -> str:
        return "GridNav-v0"

    @property
    def num_actions(self) -> int:
        return C.NUM_ACTIONS

    def make_params(self, split: str = "train", room_types=None, training: bool | None = None) -> EnvParams:
        """Params holding the scene bank of ``split`` (optionally some room types only: in a
        house, the targets that stand in a room of those types)."""
        C.check_split(split)
        rooms = tuple(range(4)) if room_types is None else _room_indices(room_types)
        if self.layout == "house":  # the houses with such rooms, their targets in such rooms
            numbers, target_rooms = [n for n in C.house_numbers(split) if set(house_room_types(n)) & set(rooms)], rooms
        else:  # the rooms of those types, all their targets
            numbers, target_rooms = C.scene_numbers(split, rooms), tuple(range(4))
        bank = make_bank(self.setup, numbers, self.grid_size, self.view_width, target_rooms, self.priors)
        limits = time_limits(split == "train" if training is None else training, self.layout)
        return EnvParams(bank=bank, max_steps=limits)

    @functools.cached_property
    def default_params(self) -> EnvParams:
        """The training split's params, built on first use and kept (not rebuilt per access)."""
        return self.make_params("train")

    def action_space(self, params: EnvParams | None = None) -> spaces.Discrete:
        return spaces.Discrete(C.NUM_ACTIONS)

    def observation_space(self, params: EnvParams | None = None) -> spaces.Dict:
        target_dim = C.WORD_VECTOR_DIM if C.SETUPS[self.setup][3] == "word_vector" else self.num_categories
        parts = {
            "view": spaces.Box(0.0, 1.0, (NUM_ROWS, self.view_width, self.num_semantic + 1), jnp.float32),
            "target": spaces.Box(-jnp.inf, jnp.inf, (target_dim,), jnp.float32),
        }
        if self.setup == "org":
            parts["detections"] = spaces.Box(0.0, 1.0, (self.num_categories, NUM_DETECTION_FEATURES), jnp.float32)
        return spaces.Dict(parts)

    def reset(self, key: jax.Array, params: EnvParams | None = None):
        params = self.default_params if params is None else params
        return self.reset_env(key, params)

    def step(self, key: jax.Array, state: EnvState, action, params: EnvParams | None = None):
        """One step with auto-reset.  Returns obs, state, reward, terminated, truncated, info."""
        params = self.default_params if params is None else params
        key_step, key_reset = jax.random.split(key)
        state_st, reward, terminated, truncated, info = self._step_state(key_step, state, action, params)
        state_re = self._reset_state(key_reset, params)
        done = terminated | truncated
        state = jax.tree.map(lambda r, s: jnp.where(done, r, s), state_re, state_st)
        obs_st = self.get_obs(state_st, params)
        if self.precomputed_views:  # two table gathers, then select (measured faster than one gather)
            obs = jax.tree.map(lambda r, s: jnp.where(done, r, s), self.get_obs(state_re, params), obs_st)
        else:  # one ray cast of the selected state; obs_st is dead code unless info is used
            obs = self.get_obs(state, params)
        if self.final_observation:
            info["final_observation"] = obs_st
        return obs, state, reward, terminated, truncated, info

    # ----------------------------------------------------------------- dynamics
    def reset_env(self, key: jax.Array, params: EnvParams):
        state = self._reset_state(key, params)
        return self.get_obs(state, params), state

    def _reset_state(self, key: jax.Array, params: EnvParams) -> EnvState:
        bank = params.bank
        # One draw of 3 x 32 random bits (one threefry call where three randints make ten);
        # the modulo bias, at most n / 2**32, is negligible.
        bits = jax.random.bits(key, (3,), jnp.uint32)

        def uniform_int(b, n):  # in [0, n)
            return (b % jnp.asarray(n).astype(jnp.uint32)).astype(jnp.int32)

        scene = uniform_int(bits[0], bank.numbers.shape[0])
        slot = uniform_int(bits[1], bank.num_targets[scene])
        which = uniform_int(bits[2], bank.num_starts[scene, slot])
        start = bank.starts[scene, slot, which].astype(jnp.int32)  # pose index // 2 (horizon 0)
        heading = start % C.NUM_HEADINGS
        cell = start // C.NUM_HEADINGS
        state = EnvState(
            agent_pos=jnp.stack([cell // self.grid_size, cell % self.grid_size]).astype(jnp.int32),
            heading=heading.astype(jnp.int32),
            horizon=jnp.zeros((), jnp.int32),
            scene=scene.astype(jnp.int32),
            room_type=self._room_type(bank, scene, slot),
            target=bank.targets[scene, slot],
            target_slot=slot.astype(jnp.int32),
            time=jnp.zeros((), jnp.int32),
            optimal_length=bank.distance[scene, slot, start * C.NUM_HORIZONS].astype(jnp.int32),
        )
        return state

    def _room_type(self, bank: SceneBank, scene, slot) -> jax.Array:
        """The type of the room holding the target: a single room's own type (one gather, the
        rooms' program as before houses existed), or in a house the target's room's."""
        if self.layout == "house":
            return bank.room_types[scene, bank.target_room[scene, slot]]
        return bank.room_type[scene]

    def step_env(self, key: jax.Array, state: EnvState, action, params: EnvParams):
        new_state, reward, terminated, truncated, info = self._step_state(key, state, action, params)
        return self.get_obs(new_state, params), new_state, reward, terminated, truncated, info

    def _step_state(self, key: jax.Array, state: EnvState, action, params: EnvParams):
        del key  # the dynamics are deterministic
        action = self._checked_action(action)
        walkable = params.bank.cell_type[state.scene] == C.CELL_FLOOR
        is_done = action == C.DONE
        success = is_done & self.target_in_view(state, params)
        pos, heading, horizon = transition(walkable, state.agent_pos, state.heading, state.horizon, action)
        time = state.time + 1
        new_state = state.replace(agent_pos=pos, heading=heading, horizon=horizon, time=time)
        reward = jnp.where(success, params.success_reward, params.step_penalty).astype(jnp.float32)
        if params.progress_reward:  # static
            gained = self.shortest_path_length(state, params) - self.shortest_path_length(new_state, params)
            reward = reward + jnp.float32(params.progress_reward) * gained.astype(jnp.float32)
        terminated = is_done
        truncated = ~terminated & (time >= params.max_steps[state.room_type])
        info = {
            "success": success,
            "episode_length": time,
            "optimal_length": state.optimal_length,
            "room_type": state.room_type,
            "scene": params.bank.numbers[state.scene],
            "target": state.target,
            "terminated": terminated,
            "truncated": truncated,
        }
        return new_state, reward, terminated, truncated, info

    def _checked_action(self, action) -> jax.Array:
        """`action` as int32, refusing a non-integer dtype (at trace time) and, with
        ``check_actions``, a value outside 0..5 (at run time, through a host callback)."""
        action = jnp.asarray(action)
        if not jnp.issubdtype(action.dtype, jnp.integer):
            raise TypeError(
                f"GridNav.step: the action must be an integer in 0..{C.NUM_ACTIONS - 1}, got dtype "
                f"{action.dtype}; cast it (e.g. jnp.argmax(...) or .astype(jnp.int32))"
            )
        action = action.astype(jnp.int32)
        if self.check_actions:
            jax.debug.callback(_raise_on_bad_action, action)
        return action

    # ----------------------------------------------------------------- observation
    def view(self, state: EnvState, params: EnvParams):
        """(sem int32 [3, W], depth float32 [3, W] in cells) seen from the state's pose (with
        a perception range, object pixels deeper than it show ``unresolved_class``)."""
        bank = params.bank
        if self.precomputed_views:
            pose = pose_index(state.agent_pos, state.heading, state.horizon, self.grid_size)
            sem = bank.view_sem[state.scene, pose].astype(jnp.int32)
            depth = bank.view_depth[state.scene, pose].astype(jnp.float32) / DEPTH_RESOLUTION
        else:
            s = state.scene
            furniture_sem = None if bank.furniture_sem is None else bank.furniture_sem[s]
            sem, depth = cast_view(
                bank.cell_type[s],
                bank.obj_cat[s],
                bank.obj_band[s],
                state.agent_pos,
                state.heading,
                state.horizon,
                self.view_width,
                furniture_sem,
            )
        if self.perception_range is None:  # static: today's program, untouched
            return sem, depth
        is_object = (sem >= C.NUM_STRUCTURAL) & (sem < C.NUM_STRUCTURAL + self.num_categories)
        return jnp.where(is_object & (depth > self.perception_range), self.unresolved_class, sem), depth

    def get_obs(self, state: EnvState, params: EnvParams) -> dict[str, jax.Array]:
        sem, depth = self.view(state, params)
        view = jnp.concatenate(
            [jax.nn.one_hot(sem, self.num_semantic, dtype=jnp.float32), (depth * self._inv_max_depth)[..., None]], -1
        )  # [3, W, num_semantic + 1]
        obs = {"view": view, "target": params.bank.target_vectors[state.target]}
        if self.setup == "org":
            obs["detections"] = self.detections(sem, depth, state.target)
        return obs

    def detections(self, sem, depth, target):
        """[n_categories, 7] detector features: visible, column box, row box, confidence, is target."""
        cats = jnp.arange(self.num_categories)
        mask = sem[None] == (C.NUM_STRUCTURAL + cats)[:, None, None]  # [n, 3, W]
        visible = mask.any((1, 2))
        cols = jnp.arange(self.view_width)[None, None, :]
        rows = jnp.arange(NUM_ROWS)[None, :, None]
        inv_w, inv_rows = jnp.float32(1.0 / self.view_width), jnp.float32(1.0 / NUM_ROWS)
        col_min = jnp.where(mask, cols, self.view_width).min((1, 2)) * inv_w
        col_max = (jnp.where(mask, cols, -1).max((1, 2)) + 1) * inv_w
        row_min = jnp.where(mask, rows, NUM_ROWS).min((1, 2)) * inv_rows
        row_max = (jnp.where(mask, rows, -1).max((1, 2)) + 1) * inv_rows
        nearest = jnp.where(mask, depth[None], jnp.inf).min((1, 2))
        confidence = 1.0 / (1.0 + nearest * 0.25)
        feats = jnp.stack([jnp.ones_like(col_min), col_min, col_max, row_min, row_max, confidence], -1)
        feats = jnp.where(visible[:, None], feats, 0.0)
        is_target = (cats == target).astype(jnp.float32)[:, None]
        return jnp.concatenate([feats, is_target], -1).astype(jnp.float32)

    def target_in_view(self, state: EnvState, params: EnvParams) -> jax.Array:
        """Whether Done would succeed now: the target is visible within the success radius."""
        return self.shortest_path_length(state, params) == 1

    def in_target_room(self, state: EnvState, params: EnvParams) -> jax.Array:
        """Whether the agent stands in the room that holds the target (always, in a single
        room; in a house, on the target room's cells, its doorways excluded)."""
        bank = params.bank
        room = bank.cell_room[state.scene, state.agent_pos[0], state.agent_pos[1]]
        return room.astype(jnp.int32) == bank.target_room[state.scene, state.target_slot]

    # ----------------------------------------------------------------- oracle
    def shortest_path_length(self, state: EnvState, params: EnvParams) -> jax.Array:
        """Shortest number of actions to success from the current pose, counting Done."""
        pose = pose_index(state.agent_pos, state.heading, state.horizon, self.grid_size)
        return params.bank.distance[state.scene, state.target_slot, pose].astype(jnp.int32)

    def optimal_action(self, state: EnvState, params: EnvParams) -> jax.Array:
        """An action on a shortest path to success (Done when the target is in view and range)."""
        bank = params.bank
        walkable = bank.cell_type[state.scene] == C.CELL_FLOOR

        def cost(action):
            pos, heading, horizon = transition(walkable, state.agent_pos, state.heading, state.horizon, action)
            pose = pose_index(pos, heading, horizon, self.grid_size)
            return bank.distance[state.scene, state.target_slot, pose].astype(jnp.int32)

        costs = jnp.stack([cost(a) for a in range(C.DONE)])
        here = self.shortest_path_length(state, params)
        return jnp.where(here == 1, C.DONE, jnp.argmin(costs)).astype(jnp.int32)


def check_perception_range(perception_range) -> float | None:
    """``perception_range`` as a float (None stays None); ValueError if it is not None or a
    positive finite number."""
    if perception_range is None:
        return None
    if (
        isinstance(perception_range, bool)
        or not isinstance(perception_range, (int, float))
        or not 0 < perception_range < float("inf")
    ):
        raise ValueError(
            f"perception_range must be None (off) or a positive number of cells (0.25 m), got {perception_range!r}"
        )
    return float(perception_range)


def _raise_on_bad_action(action) -> None:
    action = np.asarray(action)
    bad = (action < 0) | (action >= C.NUM_ACTIONS)
    if bad.any():
        raise ValueError(
            f"GridNav.step: action {action[bad].ravel()[0]} is outside 0..{C.NUM_ACTIONS - 1} "
            f"({int(bad.sum())} of {action.size} in this call)"
        )


def check_room_types(room_types) -> tuple[int, ...]:
    """Room type names or indices as indices: a ValueError naming what is wrong (for a
    program to refuse bad flags before it writes anything)."""
    rooms = _room_indices(room_types)
    twice = sorted({C.ROOM_TYPES[r] for r in rooms if rooms.count(r) > 1})
    if twice:
        raise ValueError(f"room_types lists {', '.join(twice)} more than once; name each room type once")
    return rooms


def room_names(room_types) -> tuple[str, ...]:
    """The room types an evaluation plays, as names: all four for None or (); else those of
    `check_room_types` (names or indices, a name alone one room type: "bathroom" is
    ("bathroom",), as `make_params` and `Config` read it)."""
    if room_types is None or (not isinstance(room_types, str) and len(room_types) == 0):
        return tuple(C.ROOM_TYPES)
    return tuple(C.ROOM_TYPES[r] for r in check_room_types(room_types))


def _room_indices(room_types) -> tuple[int, ...]:
    """Room type names or indices as indices; one ValueError names what is wrong."""
    if isinstance(room_types, (str, int, np.integer)):
        room_types = (room_types,)
    rooms = tuple(_room_index(r) for r in room_types)
    if not rooms:
        raise ValueError(f"room_types must name at least one room type (of {list(C.ROOM_TYPES)}), or be None for all")
    return rooms


def _room_index(room) -> int:
    if isinstance(room, str):
        if room not in C.ROOM_TYPES:
            raise ValueError(f"unknown room type {room!r}; choose from {list(C.ROOM_TYPES)}")
        return C.ROOM_TYPES.index(room)
    if isinstance(room, bool) or not isinstance(room, (int, np.integer)):
        raise ValueError(f"a room type is a name ({', '.join(C.ROOM_TYPES)}) or an index 0..3, got {room!r}")
    if not 0 <= int(room) < 4:
        raise ValueError(f"room type index must be in 0..3, got {room}")
    return int(room)


__all__ = [
    "EnvParams",
    "EnvState",
    "GridNav",
    "GRID_SIZES",
    "check_perception_range",
    "check_room_types",
    "room_names",
    "time_limits",
    "UNREACHABLE",
]
