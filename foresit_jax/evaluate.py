"""Evaluation as in Section 5: SR, SPL, and both over episodes with L^g >= 5, per room type.

SPL = (1/N) sum_i s_i L^g_i / max(L_i, L^g_i), where L^g is the oracle's shortest number of
actions to success (Done included) and L the number of actions taken (`envs.metrics`).
Episodes use the evaluation time limits (100 steps, 200 in living rooms; 300 in houses); by
default 250 per room type (in houses: per type of the room holding the target). Actions are
sampled from the policy, as SAVN does, except for methods on ORG's encoder, which take the
argmax as ORG's own evaluation does (`Method.greedy_evaluation`); ``greedy`` overrides.

An `Evaluator` holds the environments and the compiled rollouts of one setup: hold one for
a run (validation after every chunk then reuses them) and drop it to free them. The
functions `evaluate` and `evaluate_random_policy` make one when none is given.
"""

from __future__ import annotations

import functools
import inspect
from typing import Any, Callable, NamedTuple

import chex
import jax
import jax.numpy as jnp
import numpy as np

import envs
from envs.catalog import ROOM_TYPES
from envs.metrics import summarize  # (also re-exported: foresit_jax.evaluate.summarize)
from foresit_jax import imagination, maml, policy, rollout
from foresit_jax.config import Config
from foresit_jax.networks import Networks, build
from foresit_jax.rollout import ActOptions, AgentParams, BoundEnv, EpisodeStats, episode_stats


def agent_params(state, sigma2_max: float, evaluation_noise: str = "training_end") -> AgentParams:
    """From a training RunnerState.  The evaluation noise variance (`Config.evaluation_noise`):
    'training_end', the lanes' mean of Eq. 7 at the end of training (the imagination the
    policy was trained with); 'off', zero."""
    if evaluation_noise not in ("training_end", "off"):
        raise ValueError(f"evaluation_noise must be 'training_end' or 'off', got {evaluation_noise!r}")
    rho = jax.vmap(imagination.success_rate)(state.actor.agent.imagination.tracker)  # [B]
    variance = jnp.mean(imagination.noise_variance(rho, sigma2_max))
    if evaluation_noise == "off":
        variance = jnp.zeros_like(variance)
    return AgentParams(state.params, state.imagination_params, variance)


class Acting(NamedTuple):
    """A policy in memory (`make_act`, `acting_policy`): `act(params, carry, obs, first, key)
    -> (action [B], carry)` (`foresit_jax.policy.policy`, or the maml base's
    `foresit_jax.maml.policy`: pure, batched over lanes; `first` `[B]` marks an episode's
    first step), `params` what it acts with, `initial_carry(num_lanes)` its carry before a
    first step, `config` the Config it was trained with. Its first three are
    `evaluate_policy`'s first three arguments."""

    act: Callable
    params: AgentParams
    initial_carry: Callable[[int], Any]
    config: Config


class BaseActing(NamedTuple):
    """How a base acts, chosen once per Config (`base_acting`): its window (`act`, with
    `rollout.act_window`'s arguments), its step-by-step policy and that policy's carry, and
    the most episodes one rollout plays at once (None: all; the maml base copies the
    parameters per episode)."""

    act: Callable
    policy: Callable
    policy_carry: Callable
    max_lanes: int | None


def base_acting(config: Config) -> BaseActing:
    """The acting of `config`'s base: the maml base adapts its parameters inside each
    episode (`foresit_jax.maml`); every other base acts under one set (`rollout`, `policy`)."""
    if config.pieces.base_piece.adapts_in_episode:
        return BaseActing(maml.act, maml.policy, maml.policy_carry, MAX_ADAPTIVE_LANES)
    return BaseActing(rollout.act_window, policy.policy, policy.policy_carry, None)


def acting_policy(config: Config, params: AgentParams, where: str = "acting_policy") -> Acting:
    """The agent of `config` acting with `params` (`AgentParams`, the evaluation's noise
    variance set) as its evaluation acts: greedy or sampled by the method's protocol.
    Parameters whose tree or shapes are not those of `config`'s networks are refused here,
    in one line naming the first mismatch (`check_agent_params`; `where` names the caller),
    not at the first act."""
    nets, base = build(config), base_acting(config)
    env = rollout.acting_env(nets, BoundEnv(Evaluator.for_config(config).env, None)).env
    shapes = {k: jax.ShapeDtypeStruct(b.shape, b.dtype) for k, b in env.observation_space().spaces.items()}
    check_agent_params(nets, shapes, params, where)
    # (the maml base's carry holds theta_i and the running segment's observations: it reads both)
    carry = functools.partial(base.policy_carry, nets, acting=params, obs=shapes)
    return Acting(base.policy(nets, config.pieces.greedy_evaluation), params, carry, config)


def check_agent_params(nets: Networks, obs_shapes: dict, params: AgentParams, where: str) -> None:
    """A ValueError naming the first parameter whose place in the tree or whose shape differs
    between `params` (theta/omega and f_w's w) and what `nets.init` makes for observations
    of `obs_shapes` (`jax.eval_shape`: nothing runs). Catches a state trained under another
    Config (another hidden size, method or setup) before flax's ScopeParamShapeError would."""
    config = nets.config
    want = jax.eval_shape(nets.init, jax.random.PRNGKey(0), obs_shapes)
    got = (params.params, params.imagination_params)
    names = ("params", "imagination_params")
    hint = (
        f"pass the Config the state was trained with (this one: method {config.method!r}, setup {config.setup!r}, "
        f"hidden_size {config.hidden_size})"
    )
    for name, w, g in zip(names, want, got):
        w_leaves = dict(jax.tree_util.tree_flatten_with_path(w)[0])
        g_leaves = dict(jax.tree_util.tree_flatten_with_path(g)[0])
        w_paths = {jax.tree_util.keystr(k): v for k, v in w_leaves.items()}
        g_paths = {jax.tree_util.keystr(k): v for k, v in g_leaves.items()}
        missing = [k for k in w_paths if k not in g_paths]
        extra = [k for k in g_paths if k not in w_paths]
        if missing or extra:
            what = (
                f"lacks {name}{missing[0]}, which the config's networks have"
                if missing
                else f"has {name}{extra[0]}, which the config's networks do not"
            )
            raise ValueError(
                f"{where}: the state's parameters do not match the config: the state {what} "
                f"({len(missing)} missing, {len(extra)} extra); {hint}"
            )
        for k, w_leaf in w_paths.items():
            if tuple(np.shape(g_paths[k])) != tuple(w_leaf.shape):
                raise ValueError(
                    f"{where}: the state's parameters do not match the config: {name}{k} has shape "
                    f"{tuple(np.shape(g_paths[k]))}, the config's networks have {tuple(w_leaf.shape)}; {hint}"
                )


def _check_seed(seed, where: str) -> int:
    """`seed` as an int: a ValueError for a bool, a float or anything not an integer."""
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise ValueError(
            f"{where}: seed must be an int (one of the seeds trained), got {seed!r} ({type(seed).__name__})"
        )
    return int(seed)


def make_act(config: Config, state, seed: int | None = None) -> Acting:
    """The policy a `make_train` run trained, in memory, as rejax's `make_act`: from the
    final `RunnerState` that `train(key)` returns (one seed), or, with `seed`, seed `seed`
    of the states `jax.vmap(train)(keys)` returns. Acts as the evaluation does, with the
    last parameters (no model selection: that is experiments.train's):

        act = make_act(config, state)
        results = evaluate_policy(act.act, act.params, act.initial_carry, config, "test")

    Checked before acting, each in one line: `seed` is an int among the states' seeds, and
    the state's parameters have the tree and shapes of `config`'s networks (a state trained
    under another Config is refused here, not by flax at the first act)."""
    if seed is not None:
        seed = _check_seed(seed, "make_act")
    stacked = np.ndim(state.update) > 0
    if stacked != (seed is not None):
        raise ValueError(
            "make_act: give seed=i for the states of several seeds (jax.vmap(train)), and no seed for "
            f"one seed's state (its update counter has shape {np.shape(state.update)})"
        )
    if stacked:
        if not 0 <= seed < np.shape(state.update)[0]:
            raise ValueError(f"make_act: seed {seed} is not one of the {np.shape(state.update)[0]} seeds trained")
        state = jax.tree.map(lambda x: x[seed], state)
    return acting_policy(config, agent_params(state, config.sigma2_max, config.evaluation_noise), "make_act")


def outcome_metrics(outcomes: EpisodeStats, layout: str = "room") -> dict[str, float]:
    """SR, SPL, SR>=5, SPL>=5 (houses: also >=10 and >=20; in %) and counts of per-episode
    outcomes (`envs.metrics`)."""
    success, length, optimal = (np.asarray(x) for x in outcomes[:3])
    spl = np.asarray(envs.metrics.spl(success, length, optimal))
    return summarize(success, spl, optimal, envs.metrics.LONG_PATH_MINS[layout])


def random_policy_rollout(env, env_params, key: chex.PRNGKey, episodes: int, num_steps: int) -> EpisodeStats:
    """The uniformly random policy: `episodes` episodes, one per lane, each lane stepped
    `num_steps` times and only its first episode kept (the reference a trained agent must
    beat). Jittable; per-episode facts come from the environment's `info`.

    Keys: `k_reset, k_steps = split(key)`; lanes reset with `split(k_reset, episodes)`; step
    t splits its key into the actions' key and the lanes' step keys, so a policy that
    derives its keys the same way (experiments.demo's oracle) sees the same episodes."""
    k_reset, k_steps = jax.random.split(key)
    _, state = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(k_reset, episodes), env_params)

    def step(carry, key):
        state, alive = carry  # alive [N]: the lane's first episode has not ended yet
        k_act, k_env = jax.random.split(key)
        action = jax.random.randint(k_act, (episodes,), 0, env.num_actions)
        _, state, _, terminated, truncated, info = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
            jax.random.split(k_env, episodes), state, action, env_params
        )
        facts = (info["success"] & alive, alive, info["optimal_length"], info["room_type"])
        return (state, alive & ~(terminated | truncated)), facts

    (_, alive), (success, acted, optimal, room_type) = jax.lax.scan(
        step, (state, jnp.ones(episodes, bool)), jax.random.split(k_steps, num_steps)
    )  # [T, N] each
    success, length = success.any(0), acted.sum(0, dtype=jnp.int32)
    spl = envs.metrics.spl(success, length, optimal[0])
    return EpisodeStats(success, length, optimal[0], ~alive, spl, room_type[0])


# Episodes evaluated at once by methods that adapt a copy of the parameters per episode
# (maml): at `quick` sizes a copy is ~1.6M floats, and the inner loop holds about three.
MAX_ADAPTIVE_LANES = 50


def group_layout(episodes: int, max_lanes: int | None) -> tuple[int, int]:
    """(groups, lanes per group): the fewest groups of at most `max_lanes` lanes (no limit:
    None), as even as can be; groups x lanes may exceed `episodes` by less than a group."""
    if max_lanes is None or episodes <= max_lanes:
        return 1, episodes
    groups = -(-episodes // max_lanes)
    return groups, -(-episodes // groups)


class Evaluator:
    """The environment, scene banks and compiled rollouts that evaluate agents of one setup.

    Hold one for a run (validation after every chunk then compiles nothing new) and drop
    it, or call `clear()`, to free them: nothing is cached at module level. One env object
    serves every split and room type, so a compiled rollout is shared by all room types of
    the same episode length. Attributes: `env`, `params` ({(split, room): EnvParams}) and
    `compiled` ({key: jitted rollout}, keyed by (policy, config, num_steps, greedy))."""

    def __init__(
        self, setup: str = "savn", layout: str = "room", priors: bool = False, perception_range: float | None = None
    ):
        self.setup, self.layout, self.priors = setup, layout, bool(priors)
        self.env = envs.GridNav(setup=setup, layout=layout, priors=self.priors, perception_range=perception_range)
        self.perception_range = self.env.perception_range
        self.params: dict[tuple[str, str], Any] = {}
        self.compiled: dict[tuple, Any] = {}

    @staticmethod
    def scenes_of(config: Config) -> tuple[str, str, bool, float | None]:
        """(setup, layout, priors, perception_range): what an Evaluator is made for
        (`Evaluator(*scenes_of(config))`)."""
        return config.setup, config.layout, config.priors, config.perception_range

    @classmethod
    def for_config(cls, config: Config) -> "Evaluator":
        """An Evaluator of the config's scenes."""
        return cls(*cls.scenes_of(config))

    def clear(self) -> None:
        """Drop the compiled rollouts and the scene banks."""
        self.params.clear()
        self.compiled.clear()

    def room_params(self, split: str, room: str):
        """EnvParams of one room type of `split`, with the evaluation time limits."""
        if (split, room) not in self.params:
            self.params[(split, room)] = self.env.make_params(split, room_types=(room,), training=False)
        return self.params[(split, room)]

    def agent_rollout(self, config: Config, num_steps: int, greedy: bool, nets: Networks | None = None):
        """Jitted (params, w_params, env_params, key, sigma2 [N]) -> EpisodeStats [N]
        of `nets` (default `build(config)`; another one, e.g. a probe's, is compiled apart).

        The maml base keeps a copy of the parameters per episode (its inner loop adapts
        each one): its episodes run in groups of at most `MAX_ADAPTIVE_LANES` (`lax.map`),
        so that memory does not grow with the number of evaluation episodes; they are the
        episodes one rollout of all lanes would play (the same reset keys)."""
        key = ("agent", config, num_steps, greedy, None if nets is None else id(nets))
        if key not in self.compiled:
            nets, env, base = build(config) if nets is None else nets, self.env, base_acting(config)
            options = ActOptions(greedy=greedy, whole_episodes=True, record_inputs=False)

            def run_group(params, w_params, env_params, key, sigma2, reset_keys=None):
                traj = rollout.rollout(
                    nets,
                    AgentParams(params, w_params, sigma2),
                    BoundEnv(env, env_params),
                    key,
                    num_steps,
                    options,
                    reset_keys=reset_keys,
                    act=base.act,
                )
                return episode_stats(traj)

            def run(params, w_params, env_params, key, sigma2):
                episodes = sigma2.shape[0]
                groups, group = group_layout(episodes, base.max_lanes)
                if groups == 1:
                    return run_group(params, w_params, env_params, key, sigma2)
                # The episodes are those of one rollout of all lanes (its reset keys), so
                # every method and the random policy play the same ones; the groups pad
                # with repeats of the first episodes, dropped afterwards.
                k_start, k_act = jax.random.split(key)
                pad = groups * group - episodes
                reset = jax.random.split(k_start, episodes)
                reset = jnp.concatenate([reset, reset[:pad]]).reshape(groups, group, *reset.shape[1:])
                sigma2 = jnp.concatenate([sigma2, sigma2[:pad]]).reshape(groups, group)
                out = jax.lax.map(
                    lambda xs: run_group(params, w_params, env_params, *xs),
                    (jax.random.split(k_act, groups), sigma2, reset),
                )
                return jax.tree.map(lambda x: x.reshape(groups * group, *x.shape[2:])[:episodes], out)

            self.compiled[key] = jax.jit(run)
        return self.compiled[key]

    def random_rollout(self, num_steps: int, episodes: int):
        """Jitted (env_params, key) -> EpisodeStats [episodes] of `random_policy_rollout`."""
        key = ("random", num_steps, episodes)
        if key not in self.compiled:
            env = self.env
            self.compiled[key] = jax.jit(
                lambda env_params, k: random_policy_rollout(env, env_params, k, episodes, num_steps)
            )
        return self.compiled[key]

    def _per_room(self, rooms, split, key, run_room, by_length: bool = False) -> dict[str, dict[str, float]]:
        """{room: metrics, ..., "overall": metrics over the pooled episodes, and with
        `by_length` "by_length": `envs.metrics.by_length` of the pooled episodes}; `run_room`
        (env_params, num_steps, key) -> EpisodeStats; rooms get keys split from `key`."""
        results, pooled = {}, []
        for room, k in zip(rooms, jax.random.split(key, len(rooms))):
            env_params = self.room_params(split, room)
            num_steps = int(jnp.max(env_params.max_steps))
            outcomes = jax.tree.map(np.asarray, run_room(env_params, num_steps, k))
            results[room] = outcome_metrics(outcomes, self.layout)
            pooled.append(outcomes)
        pooled = jax.tree.map(lambda *parts: np.concatenate(parts), *pooled)
        results["overall"] = outcome_metrics(pooled, self.layout)
        if by_length:
            spl = np.asarray(envs.metrics.spl(pooled.success, pooled.length, pooled.optimal_length))
            buckets = envs.metrics.LENGTH_BUCKETS_OF[self.layout]
            results["by_length"] = envs.metrics.by_length(pooled.success, spl, pooled.optimal_length, buckets)
        return results

    def _check(self, config: Config, split: str, episodes_per_room: int) -> None:
        if split not in ("train", "val", "test"):
            raise ValueError(f"split must be 'val' or 'test' (or 'train'), got {split!r}")
        if episodes_per_room < 1:
            raise ValueError(f"episodes_per_room must be >= 1, got {episodes_per_room}")
        if config.setup != self.setup:
            raise ValueError(f"this Evaluator is for setup {self.setup!r}, the config's is {config.setup!r}")
        if config.layout != self.layout:
            raise ValueError(
                f"this Evaluator is for layout {self.layout!r}, the config's is {config.layout!r}; "
                f"make one with Evaluator(setup, layout={config.layout!r})"
            )
        if config.priors != self.priors:
            raise ValueError(
                f"this Evaluator is for priors={self.priors}, the config's is {config.priors}; "
                "make one with Evaluator.for_config(config)"
            )
        if config.perception_range != self.perception_range:
            raise ValueError(
                f"this Evaluator is for perception_range={self.perception_range}, the config's is "
                f"{config.perception_range}; make one with Evaluator.for_config(config)"
            )

    def evaluate(
        self,
        agent_params: AgentParams,
        config: Config,
        split: str = "test",
        key: chex.PRNGKey | None = None,
        episodes_per_room: int = 250,
        greedy: bool | None = None,
        room_types: tuple[str, ...] | None = None,
        by_length: bool = False,
        agent: Networks | None = None,
    ) -> dict[str, dict[str, float]]:
        """Run `episodes_per_room` episodes in each room type of `split` ("val" or "test").

        Returns {"overall": metrics, "kitchen": metrics, ...} with metrics from `summarize`,
        and with `by_length` also "by_length": SR/SPL by bucket of L^g (`envs.metrics.by_length`).
        agent: the acting networks (default `networks.build(config)`; e.g. a probe's
        `probes.shuffled`); keep the object for as long as this Evaluator, its compiled
        rollout is cached under the object's id.
        """
        self._check(config, split, episodes_per_room)
        key = jax.random.PRNGKey(0) if key is None else key
        greedy = config.pieces.greedy_evaluation if greedy is None else bool(greedy)
        rooms = envs.gridnav.room_names(room_types or config.room_types)
        sigma2 = jnp.full((episodes_per_room,), agent_params.noise_variance, jnp.float32)

        def run_room(env_params, num_steps, k):
            run = self.agent_rollout(config, num_steps, greedy, agent)
            return run(agent_params.params, agent_params.imagination_params, env_params, k, sigma2)

        return self._per_room(rooms, split, key, run_room, by_length)

    def evaluate_random_policy(
        self, config: Config, split: str = "test", key: chex.PRNGKey | None = None, episodes_per_room: int = 250
    ) -> dict[str, dict[str, float]]:
        """The uniformly random policy on the same room types and number of episodes."""
        self._check(config, split, episodes_per_room)
        key = jax.random.PRNGKey(0) if key is None else key
        rooms = tuple(config.room_types or ROOM_TYPES)

        def run_room(env_params, num_steps, k):
            return self.random_rollout(num_steps, episodes_per_room)(env_params, k)

        return self._per_room(rooms, split, key, run_room)


def evaluate(
    agent_params: AgentParams,
    config: Config,
    split: str = "test",
    key: chex.PRNGKey | None = None,
    episodes_per_room: int = 250,
    greedy: bool | None = None,
    room_types: tuple[str, ...] | None = None,
    evaluator: Evaluator | None = None,
) -> dict[str, dict[str, float]]:
    """`Evaluator.evaluate` (with a new Evaluator unless one is given)."""
    evaluator = Evaluator.for_config(config) if evaluator is None else evaluator
    return evaluator.evaluate(agent_params, config, split, key, episodes_per_room, greedy, room_types)


def evaluate_random_policy(
    config: Config,
    split: str = "test",
    key: chex.PRNGKey | None = None,
    episodes_per_room: int = 250,
    evaluator: Evaluator | None = None,
) -> dict[str, dict[str, float]]:
    """`Evaluator.evaluate_random_policy` (with a new Evaluator unless one is given)."""
    evaluator = Evaluator.for_config(config) if evaluator is None else evaluator
    return evaluator.evaluate_random_policy(config, split, key, episodes_per_room)


def policy_episodes(
    policy_fn: Callable, params, carry, env: BoundEnv, key: chex.PRNGKey, num_steps: int, num_lanes: int
) -> EpisodeStats:
    """One whole episode per lane of any batched policy function
    `(params, carry, obs, first, key) -> (action [B], carry)`, padded to `num_steps`, as
    `rollout.rollout` plays them: the lanes reset with `split(split(key)[0], B)`, and the
    steps' keys come from `split(key)[1]` by the policy's `step_keys` schedule
    (`policy.StepPolicy`; a plain function gets `policy.lockstep_keys`: step t gets
    `split(k, num_steps)[t]` and the environment steps with `split(split(that key, 3)[2], B)`);
    only each lane's first episode counts."""
    k_start, k_act = jax.random.split(key)
    obs, env_state = env.reset(jax.random.split(k_start, num_lanes))
    step_keys = getattr(policy_fn, "step_keys", policy.lockstep_keys)
    policy_keys, env_keys = step_keys(k_act, num_steps, num_lanes)

    def step(state, keys):
        obs, env_state, carry, alive, first = state
        policy_key, env_key = keys
        action, carry = policy_fn(params, carry, obs, first, policy_key)
        obs, env_state, _, term, trunc, info = env.step(env_key, env_state, action)
        done = term | trunc
        out = (alive, info["success"] & alive, (term | trunc) & alive, info["optimal_length"], info["room_type"])
        return (obs, env_state, carry, alive & ~done, done), out

    first = jnp.ones((num_lanes,), bool)
    _, (valid, success, ended, optimal, room) = jax.lax.scan(
        step, (obs, env_state, carry, first, first), (policy_keys, env_keys)
    )
    length = jnp.sum(valid.astype(jnp.int32), axis=0)
    success = jnp.any(success, axis=0)
    spl = envs.metrics.spl(success, length, optimal[0])
    return EpisodeStats(success, length, optimal[0], jnp.any(ended, axis=0), spl, room[0])


def _described(x) -> str:
    """What a policy returned, in a few words (for `check_policy_return`'s messages)."""
    if isinstance(x, (tuple, list)):
        return f"a {type(x).__name__} of {len(x)} values"
    if hasattr(x, "shape") and hasattr(x, "dtype"):
        return f"an array of shape {tuple(x.shape)} and dtype {x.dtype}"
    return f"a {type(x).__name__}"


def check_policy_return(out, carry, num_lanes: int, where: str = "evaluate_policy") -> None:
    """Refuse, in one line saying what was expected and what came, a policy's return that is
    not `(actions [num_lanes] of an integer dtype, carry)` with `carry` of the tree, shapes
    and dtypes of the carry it was given. Runs while the policy is traced (shapes only:
    free at run time), so a bad policy fails here, not inside `lax.scan` or `vmap`."""
    expected = f"(actions [{num_lanes}] of an integer dtype, carry)"
    if not isinstance(out, (tuple, list)) or len(out) != 2:
        missing = " (no carry: return the carry too, even None for a policy without one)"
        raise TypeError(
            f"{where}: the policy must return {expected}; it returned {_described(out)}"
            + (missing if not isinstance(out, (tuple, list)) or len(out) == 1 else "")
        )
    actions, new_carry = out
    shape = tuple(np.shape(actions))
    if shape != (num_lanes,):
        scalar = " (a scalar: the policy is batched, one action per lane)" if shape == () else ""
        raise ValueError(
            f"{where}: the policy's actions must have shape ({num_lanes},), one per lane; got shape {shape}{scalar}"
        )
    dtype = jnp.result_type(actions)
    if not jnp.issubdtype(dtype, jnp.integer):
        raise TypeError(
            f"{where}: the policy's actions must have an integer dtype (actions 0..{envs.catalog.NUM_ACTIONS - 1}); "
            f"got {dtype} (cast them: jnp.argmax(...) or .astype(jnp.int32))"
        )
    given, got = jax.tree.structure(carry), jax.tree.structure(new_carry)
    if given != got:
        raise TypeError(
            f"{where}: the policy must return the carry it was given, updated (the structure of "
            f"initial_carry({num_lanes})); it returned {_described(new_carry)} of structure {got}, not {given}"
        )
    for (path, a), b in zip(jax.tree_util.tree_flatten_with_path(carry)[0], jax.tree.leaves(new_carry)):
        if np.shape(a) != np.shape(b) or jnp.result_type(a) != jnp.result_type(b):
            raise TypeError(
                f"{where}: the policy's returned carry{jax.tree_util.keystr(path)} has shape {tuple(np.shape(b))} "
                f"and dtype {jnp.result_type(b)}; the carry it was given has {tuple(np.shape(a))} and "
                f"{jnp.result_type(a)}"
            )


def _raise_on_bad_policy_action(action) -> None:
    action = np.asarray(action)
    bad = (action < 0) | (action >= envs.catalog.NUM_ACTIONS)
    if bad.any():
        raise ValueError(
            f"evaluate_policy: the policy chose action {action[bad].ravel()[0]}, outside "
            f"0..{envs.catalog.NUM_ACTIONS - 1} ({int(bad.sum())} of {action.size} lanes at this step)"
        )


def checked_policy(policy_fn: Callable, num_lanes: int, check_actions: bool = False) -> Callable:
    """`policy_fn` whose every return is checked by `check_policy_return` while it is traced
    (its first call) and, with `check_actions`, whose actions outside 0..5 raise at run time
    (a host callback per step, as `envs.GridNav(check_actions=True)`: for debugging). Keeps
    the policy's `step_keys` (the keys `policy_episodes` gives it)."""

    def checked(params, carry, obs, first, key):
        out = policy_fn(params, carry, obs, first, key)
        check_policy_return(out, carry, num_lanes)
        actions, carry = out
        if check_actions:
            jax.debug.callback(_raise_on_bad_policy_action, actions)
        return actions, carry

    checked.step_keys = getattr(policy_fn, "step_keys", policy.lockstep_keys)
    return checked


def _check_policy_signature(policy_fn: Callable) -> None:
    """A TypeError when `policy_fn` cannot take `(params, carry, obs, first, key)`."""
    if not callable(policy_fn):
        raise TypeError(
            f"evaluate_policy: policy_fn must be a function (params, carry, obs, first, key), got {_described(policy_fn)}"
        )
    try:
        signature = inspect.signature(policy_fn)
    except (TypeError, ValueError):  # a builtin or an object without one: its first call tells
        return
    try:
        signature.bind(*range(5))
    except TypeError:
        raise TypeError(
            f"evaluate_policy: policy_fn must take 5 arguments (params, carry, obs, first, key); "
            f"{getattr(policy_fn, '__name__', type(policy_fn).__name__)}{signature} does not"
        ) from None


def evaluate_policy(
    policy_fn: Callable,
    params,
    initial_carry: Callable[[int], Any],
    config: Config,
    split: str = "test",
    key: chex.PRNGKey | None = None,
    episodes_per_room: int = 250,
    room_types: tuple[str, ...] | None = None,
    check_actions: bool = False,
) -> dict[str, dict[str, float]]:
    """SR, SPL and SR by path length of any policy, the user's own included, on the episodes
    `Evaluator.evaluate` plays for `config`'s scenes (setup, layout, priors; its room types
    unless `room_types`) with `key` (PRNGKey(0) by default; the reports' test episodes of
    seed s: `experiments.load`'s `test_key(s)`): {"overall": ..., room: ..., "by_length": ...}.
    Each room's and "overall"'s metrics are `summarize`'s: "SR", "SPL", "SR>=5", "SPL>=5"
    (houses: also >=10 and >=20) in percent (0..100, not fractions), and "episodes", a count.

    policy_fn: `(params, carry, obs, first, key) -> (action [B], carry)`, batched over lanes
    (`base_acting(config).policy(nets)` is the agent's; see `policy_episodes` for the keys it gets);
    initial_carry: `num_lanes -> carry`. The agent's own policy gives `Evaluator.evaluate`'s
    numbers exactly (tests/agent/test_policy.py). The privileged `oracle` reads the goal view: its
    observations come from the environment wrapped as `rollout.acting_env` wraps it.

    The policy is checked on its first call (while it is traced: free at run time): it must
    take those five arguments and return a pair, its actions of shape [B] (B =
    `episodes_per_room`) and an integer dtype, and a carry of the tree, shapes and dtypes of
    the one it was given; anything else is refused in one line saying what was expected and
    what came. An action outside 0..5 is a step that changes nothing (as `envs.GridNav`'s);
    `check_actions=True` raises on one instead (a host callback per step: for debugging, as
    `envs.make_gymnax(..., check_actions=True)`)."""
    _check_policy_signature(policy_fn)
    if not callable(initial_carry):
        raise TypeError(
            f"evaluate_policy: initial_carry must be a function num_lanes -> carry, got {_described(initial_carry)}"
        )
    evaluator = Evaluator.for_config(config)
    evaluator._check(config, split, episodes_per_room)
    key = jax.random.PRNGKey(0) if key is None else key
    rooms = envs.gridnav.room_names(room_types or config.room_types)
    env = rollout.acting_env(build(config), BoundEnv(evaluator.env, None)).env
    checked = checked_policy(policy_fn, episodes_per_room, check_actions)
    compiled = {}

    def run_room(env_params, num_steps, k):
        if num_steps not in compiled:  # one program per time limit (room types share one in rooms)
            compiled[num_steps] = jax.jit(
                lambda p, c, e, k: policy_episodes(checked, p, c, BoundEnv(env, e), k, num_steps, episodes_per_room)
            )
        return compiled[num_steps](params, initial_carry(episodes_per_room), env_params, k)

    return evaluator._per_room(rooms, split, key, run_room, by_length=True)
