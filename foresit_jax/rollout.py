"""Acting: the records one window of every lane reads and writes, and plain functions.

The functions take the `Networks` record of a Config (`foresit_jax.networks.build`: the
modules, the Config, f_w) and drive any environment with the GridNav API (``reset`` /
``step`` vmapped over lanes; per-episode facts read from the step's ``info``: ``success``,
``optimal_length``, ``room_type``), never the environment's state.

Acting takes three records: `AgentParams` (what acts: theta/omega, f_w's w, the noise
variance), `BoundEnv` (the environment bound to its parameters once) and `ActOptions` (how:
greedy or sampled, packed windows or whole episodes, whether to record the inputs).
`act_window` runs every lane for a window of `num_steps` steps from an `ActorState` and returns
the next `ActorState`, the window's `Trajectory` (what each step recorded) and its
`WindowEnd` (the state after it). Lanes never idle: episodes follow one
another inside a window (the environment auto-resets), and an episode cut at the window's
edge continues in the next one with its LSTM carry, s_0, i_tau, step count and (for the
attention critic) the states it has seen so far (`ActorState.memory`). At each episode's
start the LSTM carry and the previous action probabilities are zeroed and i_tau is
imagined from s_0 with the lane's current noise variance (Eq. 6-7; every K steps for the
`int` ablation); each ended episode's outcome updates the lane's success tracker (rho).

`ActOptions(whole_episodes=True)` is SAVN's layout: every lane starts a fresh episode and only its
first episode counts (`valid`); what follows it in the window is padding. Evaluation uses
it (`rollout`), and so does training with `Config.rollout='episodes'` (the reference).

This module is the a3c base's acting, and every base's step: `act_window` runs a window
under one parameter set. The maml base adapts each lane's parameters inside its episode
(`foresit_jax.maml.act`, which calls `act_window` for each segment, giving it an
`Adaptation`); the Trainer and the Evaluator choose between the two once, by the base.
The same agent step by step, for a user's own loop, is `foresit_jax.policy`.

    nets = networks.build(config)
    params, w = nets.init(key, obs)
    traj = rollout(nets, AgentParams(params, w, jnp.zeros(8)), BoundEnv(env, env_params), key, 100)
"""

from __future__ import annotations

import functools
from typing import Any, Callable, NamedTuple, Optional

import chex
import jax
import jax.numpy as jnp
from flax import struct

import envs.metrics
from envs.wrappers import CueWrapper, GoalViewWrapper
from foresit_jax import distributions, imagination
from foresit_jax.lstm import LowRankUpdate, LSTMCarry, initial_carry, lane_copies, reset_carry
from foresit_jax.methods import ImaginationVariant
from foresit_jax.networks import EncoderInputs, Networks


class AgentParams(NamedTuple):
    """What acts: theta/omega, w, and the imagination noise's variance."""

    params: Any  # the ActorCritic's parameters (encoder, policy, critic; maml's L_phi)
    imagination_params: Any  # f_w's parameters w
    noise_variance: Optional[chex.Array] = None  # [] or [B] fixed (evaluation); None: each
    # lane's Eq. 7 from its success tracker (training)


@struct.dataclass
class BoundEnv:
    """An environment with the GridNav API bound to its parameters (a split's scene bank),
    once, by whoever holds both (the Trainer, an evaluation room)."""

    env: Any = struct.field(pytree_node=False)
    params: Any = None

    def reset(self, keys: chex.Array):
        """Every lane reset, one key each: (obs, env_state), leaves `[B, ...]`."""
        return jax.vmap(self.env.reset, in_axes=(0, None))(keys, self.params)

    def step(self, keys: chex.Array, env_state, action: chex.Array):
        """Every lane stepped (auto-reset): (obs, env_state, reward, terminated, truncated, info)."""
        return jax.vmap(self.env.step, in_axes=(0, 0, 0, None))(keys, env_state, action, self.params)


class ActOptions(NamedTuple):
    """How a window is acted."""

    greedy: bool = False  # the argmax action (ORG's evaluation) instead of a sample
    whole_episodes: bool = False  # SAVN's layout: each lane's first episode counts, the rest is padding
    record_inputs: bool = True  # keep each step's encoder and policy inputs (Trajectory.inputs, the replay's)
    step_keys: Optional[chex.Array] = None  # [num_steps, 2] the steps' keys instead of split(key) (so that
    # two windows can replay exactly one longer window's steps)


class Adaptation(NamedTuple):
    """What the maml base's inner loop gives a window it acts under adapted parameters
    (`foresit_jax.maml.adaptive_act` fills it; `act_window` reads it); every field may be None.

    alive: `[B]` bool, with `whole_episodes`, which lanes' counted episode is still running
      at the window's start (None: all; a window that continues an earlier one of the same
      whole-episode rollout passes what that one left);
    lstm_update: a low-rank change of the LSTM's kernels (the lanes' adapted kernels);
    gate_offsets: `[num_steps, B, 4H]` added to each step's gate pre-activations (zeros
      whose gradient is the pre-activations')."""

    alive: Optional[chex.Array] = None
    lstm_update: Optional[LowRankUpdate] = None
    gate_offsets: Optional[chex.Array] = None


class ActorState(NamedTuple):
    """What each lane carries from one window to the next; leaves `[B, ...]`."""

    env_state: Any  # the environment's state (opaque to the agent)
    obs: Any  # observation dict to act on next, leaves [B, ...]
    lstm: LSTMCarry  # (c, h) [B, H] each; zeros when a new episode begins
    prev_probs: chex.Array  # [B, A] previous action probabilities (zeros at an episode start)
    imagined: chex.Array  # [B, H] the running episode's i_tau
    s_0: chex.Array  # [B, H] the running episode's first state
    episode_step: chex.Array  # [B] int32 index of the next state in its episode (0: new episode)
    memory: Optional[chex.Array]  # [B, M, H] the running episode's states so far (attention critic; else None)
    tracker: imagination.SuccessTracker  # [B, window] outcomes of each lane's last episodes (rho)


class StepInputs(NamedTuple):
    """What the encoder and the policy saw at each step of a window (for the replay)."""

    obs: Any  # observation dict, leaves [T, B, ...]
    prev_action_probs: chex.Array  # [T, B, A]
    imagined: Optional[chex.Array]  # [T, B, H] i_tau given to the policy head; None if the head takes none
    encoder_imagined: Optional[chex.Array] = None  # [T, B, H] i_tau given to the encoder (zeros at an
    # episode's first step); None unless Config.imagination_input == 'encoder'


class Trajectory(NamedTuple):
    """What every step of a window recorded, `[T, B, ...]` time-major (one step of
    `act_window` records one, `[B, ...]`; the scan stacks them). What follows the
    window is its `WindowEnd`."""

    states: chex.Array  # [T, B, H] s_t (LSTM hidden state)
    logits: chex.Array  # [T, B, A]
    actions: chex.Array  # [T, B] int32
    rewards: chex.Array  # [T, B]
    terminated: chex.Array  # [T, B] bool, Done taken
    truncated: chex.Array  # [T, B] bool, time limit reached
    valid: chex.Array  # [T, B] bool, the step enters the loss (all of them when packed)
    success: chex.Array  # [T, B] bool, successful Done at this step
    episode_step: chex.Array  # [T, B] int32 position of s_t in its episode (0 at its start)
    s_0: chex.Array  # [T, B, H] first state of the step's episode
    optimal_length: chex.Array  # [T, B] int32 L^g of the step's episode
    room_type: chex.Array  # [T, B] int32
    inputs: Optional[StepInputs] = None  # recorded with record_inputs=True


class WindowEnd(NamedTuple):
    """What follows a window, per lane: the state s_T after its last step (it bootstraps
    an episode the window cut, V(s*_T) in Eq. 8, and is the critic's last key) and its
    position in its episode. After whole episodes the state is zeros: nothing is
    bootstrapped (the position is the lanes' next one, as after any window)."""

    state: chex.Array  # [B, H] s_T, without gradient
    episode_step: chex.Array  # [B] int32


class EpisodeStats(NamedTuple):
    """Per-episode facts, `[N]` for a batch of whole episodes (one per lane: `episode_stats`,
    evaluation's; `foresit_jax.evaluate.random_policy_rollout`) or `[T, B]` for the steps
    of a packed window (`ended_episodes`)."""

    success: chex.Array  # bool, a successful Done
    length: chex.Array  # int32 L: actions taken, Done included
    optimal_length: chex.Array  # int32 L^g: the oracle's shortest number of actions
    ended: chex.Array  # bool, the episode ended (Done or time limit) within the rollout
    spl: Optional[chex.Array] = None  # float32 success * L^g / max(L, L^g); None where not computed
    room_type: Optional[chex.Array] = None  # int32; None where not recorded


def episode_stats(traj: Trajectory) -> EpisodeStats:
    """Per-lane statistics of a whole-episode rollout (each lane's first episode)."""
    valid = traj.valid
    length = jnp.sum(valid.astype(jnp.int32), axis=0)
    success = jnp.any(traj.success & valid, axis=0)
    ended = jnp.any((traj.terminated | traj.truncated) & valid, axis=0)
    opt = traj.optimal_length[0]
    spl = envs.metrics.spl(success, length, opt)
    return EpisodeStats(success, length, opt, ended, spl, traj.room_type[0])


def ended_episodes(traj: Trajectory) -> tuple[chex.Array, EpisodeStats]:
    """The episodes that ended inside a window: (`ended [T, B]` bool, per-step
    `EpisodeStats` `[T, B]` meaningful where `ended`), for metrics over packed windows."""
    ended = (traj.terminated | traj.truncated) & traj.valid
    length = traj.episode_step + 1
    success = traj.success & ended
    spl = envs.metrics.spl(success, length, traj.optimal_length)
    return ended, EpisodeStats(success, length, traj.optimal_length, ended, spl, traj.room_type)


# ---------------------------------------------------------------------- acting


def start(
    nets: Networks, key, env: BoundEnv, num_lanes: int, memory_size: int = 0, tracker=None, reset_keys=None
) -> ActorState:
    """Every lane at the start of a fresh episode. memory_size: states of an episode the
    attention critic can remember across windows (the training time limit; 0 when nothing
    is carried across windows: `memory` is then None). tracker: per-lane success trackers
    to keep (fresh ones by default). reset_keys: `[num_lanes, ...]` the lanes' reset keys
    (default: `split(key, num_lanes)`)."""
    if isinstance(num_lanes, bool) or not isinstance(num_lanes, int) or num_lanes < 1:
        raise ValueError(f"num_lanes must be a positive int, got {num_lanes!r}")
    cfg = nets.config
    env = acting_env(nets, env)
    reset_keys = jax.random.split(key, num_lanes) if reset_keys is None else reset_keys
    obs, env_state = env.reset(reset_keys)
    hidden = cfg.hidden_size
    zeros = jnp.zeros((num_lanes, hidden), jnp.float32)
    if tracker is None:
        one = imagination.tracker_init(cfg.success_window)
        tracker = lane_copies(one, num_lanes)
    return ActorState(
        env_state=env_state,
        obs=obs,
        lstm=initial_carry((num_lanes,), hidden),
        prev_probs=jnp.zeros((num_lanes, cfg.num_actions), jnp.float32),
        imagined=zeros,
        s_0=zeros,
        episode_step=jnp.zeros((num_lanes,), jnp.int32),
        memory=jnp.zeros((num_lanes, memory_size, hidden), jnp.float32) if memory_size else None,
        tracker=tracker,
    )


def acting_env(nets: Networks, env: BoundEnv) -> BoundEnv:
    """The environment `nets` acts in: `env` itself, or, for an imagination that reads the
    goal view (the privileged `oracle`) or a cue (`optaction`, `compass`, `startcompass`),
    `env` wrapped to carry it (`envs.wrappers.GoalViewWrapper`, `envs.wrappers.CueWrapper`;
    built for those methods alone, so no other program changes)."""
    variant = nets.imagination_variant
    if variant.reads_cue and not isinstance(env.env, CueWrapper):
        return BoundEnv(CueWrapper(env.env, variant.cue), env.params)
    if not variant.reads_goal_view or isinstance(env.env, GoalViewWrapper):
        return env
    return BoundEnv(GoalViewWrapper(env.env), env.params)


def goal_latent(nets: Networks, params, kernels, obs) -> chex.Array:
    """The agent's own latent of its episodes' goal views `[B, H]` (privileged; the
    `oracle` imagination's i_tau before noise): the encoder and one LSTM step from a fresh
    carry (zero carry and previous action probabilities, as at an episode's first step)
    on `obs`'s goal view (`GoalViewWrapper.goal_of`), under `kernels`."""
    lanes = obs["target"].shape[:-1]
    hidden = nets.config.hidden_size
    probs = jnp.zeros(lanes + (nets.config.num_actions,), jnp.float32)
    encoder_imagined = jnp.zeros(lanes + (hidden,), jnp.float32) if nets.imagination_in_encoder else None
    inputs = one_step(GoalViewWrapper.goal_of(obs), probs, encoder_imagined)
    first = jnp.ones((1,) + lanes, bool)
    return nets.model.apply(params, initial_carry(lanes, hidden), inputs, first, kernels, method="encode")[1][0]


def one_step(obs, prev_action_probs, encoder_imagined) -> EncoderInputs:
    """The encoder's inputs of one step of every lane (leaves `[B, ...]`) as a window of
    one, `[1, B, ...]` (`ActorCritic.encode` at T = 1)."""
    return EncoderInputs(*jax.tree.map(lambda x: x[None], (obs, prev_action_probs, encoder_imagined)))


def cue_latent(nets: Networks, obs) -> chex.Array:
    """A privileged cue as i_tau `[B, H]`: `obs["cue"]` `[B, K]` zero-padded to H, exact
    (no noise; `Config` requires sigma2_max=0), lanes reordered by `nets.permute`."""
    cue = obs["cue"]
    cue = (nets.permute or (lambda x: x))(cue)
    return jnp.pad(cue, [(0, 0)] * (cue.ndim - 1) + [(0, nets.config.hidden_size - cue.shape[-1])])


def encoder_imagined(nets: Networks, actor: ActorState) -> Optional[chex.Array]:
    """The i_tau the encoder sees at the lanes' next step `[B, H]`: the running episode's,
    zeros at an episode's first step (i_tau is imagined from that step's output); None
    unless i_tau enters the encoder. A cue is read from the observation, which exists
    before the step's state: the encoder sees the step's own cue, at the first step too."""
    if not nets.imagination_in_encoder:
        return None
    if nets.imagination_variant.reads_cue:
        return cue_latent(nets, actor.obs)
    return jnp.where((actor.episode_step == 0)[:, None], 0.0, actor.imagined)


def _imagine(nets: Networks, w_params, s_t, goal, key, noise_variance, goal_latent_fn) -> chex.Array:
    """i_tau `[B, H]` from its source (the ImaginationVariant piece), stop-gradient (the
    policy loss never trains f_w or, through it, s_0). learned: f_w([s_t : g]) +
    N(0, sigma2) (Eq. 6), or with `imagination_noise='input'` f_w([s_t : g] + N(0, sigma2))
    (Algorithm 1); random: tanh(N(0, v)); goal_view: the goal view's latent + N(0, sigma2).
    `nets.permute` reorders the lanes of i_tau's inputs (the probe's shuffle)."""
    cfg, source = nets.config, nets.imagination_variant.source
    permute = nets.permute or (lambda x: x)
    if source == "random":
        return imagination.random_imagination(key, s_t.shape, cfg.rnd_variance)
    if source == "goal_view":
        return jax.lax.stop_gradient(imagination.add_imagination_noise(key, permute(goal_latent_fn()), noise_variance))
    s_t, goal = permute(s_t), permute(goal)
    if cfg.imagination_noise == "input":
        s_in, goal_in = imagination.add_input_noise(key, jax.lax.stop_gradient(s_t), goal, noise_variance)
        return jax.lax.stop_gradient(nets.imagine(w_params, s_in, goal_in))
    imagined = nets.imagine(w_params, jax.lax.stop_gradient(s_t), goal)
    return jax.lax.stop_gradient(imagination.add_imagination_noise(key, imagined, noise_variance))


def renews(variant: ImaginationVariant, episode_step: chex.Array, interval: int) -> chex.Array:
    """Whether i_tau is (re)imagined at this step of the episode, `[...]` bool: at every
    `interval`-th step with the `int` ablation's `renew_every_k`, else at the first."""
    if variant.renew_every_k:
        return episode_step % interval == 0
    return episode_step == 0


def imagined_at_step(
    nets: Networks,
    acting: AgentParams,
    actor: ActorState,
    s_t: chex.Array,
    key: chex.PRNGKey,
    goal_latent_fn: Optional[Callable[[], chex.Array]] = None,
) -> chex.Array:
    """i_tau for a step `[B, H]` (Eq. 6-7): renewed where the ImaginationVariant piece says
    (an episode's first step; every K steps for `int`) from s_t (= s_0 at the first step)
    by f_w (`acting.imagination_params`), with noise of each lane's variance
    (`acting.noise_variance` `[B]`, or Eq. 7 from its success tracker), else the running
    episode's. Unchanged without imagination. goal_latent_fn: `() -> [B, H]`, the goal
    view's latent (`goal_latent`), for an imagination that reads it (called only where
    i_tau is renewed)."""
    cfg, variant = nets.config, nets.imagination_variant
    if not variant.uses_imagination:
        return actor.imagined
    if variant.reads_cue:  # the step's own cue, every step
        return cue_latent(nets, actor.obs)
    noise_variance = acting.noise_variance
    if noise_variance is None:
        noise_variance = imagination.noise_variance(jax.vmap(imagination.success_rate)(actor.tracker), cfg.sigma2_max)
    renew = renews(variant, actor.episode_step, cfg.int_interval)  # [B]
    goal = actor.obs["target"]

    def renewed():
        mask = renew[:, None]  # [B, 1], before the imagination (the order of the lowered program's ops)
        imagined = _imagine(nets, acting.imagination_params, s_t, goal, key, noise_variance, goal_latent_fn)
        return jnp.where(mask, imagined, actor.imagined)

    return jax.lax.cond(jnp.any(renew), renewed, lambda: actor.imagined)


def agent_step(nets: Networks, acting: AgentParams, kernels, actor: ActorState, key: chex.PRNGKey, gate_offset):
    """The agent's half of a step: `encode` at T = 1, i_tau imagined from its s_t, then
    `heads` -> (LSTM carry, s_t, logits, i_tau, s_0, the encoder's i_tau). `key`: i_tau's
    noise. Acting's window (`act_window`) and the step-by-step policy (`foresit_jax.policy`) both run
    it, so they compute alike."""
    first = actor.episode_step == 0  # [B]
    seen_imagined = encoder_imagined(nets, actor)  # [B, H] or None
    offsets = None if gate_offset is None else gate_offset[None]
    lstm, states = nets.model.apply(
        acting.params,
        actor.lstm,
        one_step(actor.obs, actor.prev_probs, seen_imagined),
        first[None],
        kernels,
        offsets,
        method="encode",
    )
    s_t = states[0]
    s_0 = jnp.where(first[:, None], s_t, actor.s_0)
    goal_latent_fn = None  # the oracle's: computed only where i_tau is renewed
    if nets.imagination_variant.reads_goal_view:
        goal_latent_fn = functools.partial(goal_latent, nets, acting.params, kernels, actor.obs)
    imagined = imagined_at_step(nets, acting, actor, s_t, key, goal_latent_fn)  # [B, H]
    logits = nets.model.apply(acting.params, s_t, imagined, method="heads")
    return lstm, s_t, logits, imagined, s_0, seen_imagined


def act_window(
    nets: Networks,
    acting: AgentParams,
    env: BoundEnv,
    actor: ActorState,
    key: chex.PRNGKey,
    num_steps: int,
    options: ActOptions = ActOptions(),
    adapt: Adaptation = Adaptation(),
) -> tuple[ActorState, Trajectory, WindowEnd]:
    """Run every lane `num_steps` steps from `actor` under one parameter set (see the module
    docstring; the a3c base's window, and each segment of the maml base's): returns (the
    actor state after the window, the window's Trajectory, what follows it). Each step
    is the agent's (`agent_step`: `ActorCritic.encode` at T = 1, i_tau, `ActorCritic.heads`),
    then the environment's. `adapt`: what the maml base's inner loop gives a window
    (`Adaptation`; the default: nothing)."""
    if adapt.alive is None and nets.method.base_piece.adapts_in_episode:
        raise ValueError(
            f"act_window plays one parameter set, and method {nets.method.name!r} adapts its parameters "
            "inside each episode (the maml base): use foresit_jax.maml.act (Trainer.act_window, "
            "foresit_jax.evaluate.base_acting(config).act)"
        )
    params, lanes = acting.params, jnp.arange(actor.episode_step.shape[0])
    env = acting_env(nets, env)
    kernels = nets.model.apply(params, adapt.lstm_update, method="lstm_kernels")  # once, outside the loop
    in_head, carries_gradient = nets.imagination_in_head, nets.method.action_probs_carry_gradient

    def step(carry, xs):
        actor, alive = carry
        key, gate_offset = xs
        k_imag, k_act, k_env = jax.random.split(key, 3)
        lstm, s_t, logits, imagined, s_0, seen_imagined = agent_step(nets, acting, kernels, actor, k_imag, gate_offset)
        policy_input = imagined if in_head else None
        action = distributions.greedy(logits) if options.greedy else distributions.sample(k_act, logits)
        memory = remember(actor, s_t, lanes)
        obs, env_state, reward, term, trunc, info = env.step(
            jax.random.split(k_env, lanes.shape[0]), actor.env_state, action
        )
        done = term | trunc
        tracker = jax.vmap(imagination.tracker_update)(actor.tracker, info["success"], done & alive)
        seen = StepInputs(actor.obs, actor.prev_probs, policy_input, seen_imagined) if options.record_inputs else None
        out = Trajectory(
            states=s_t,
            logits=logits,
            actions=action,
            rewards=reward,
            terminated=term,
            truncated=trunc,
            valid=alive,
            success=info["success"] & alive,
            episode_step=actor.episode_step,
            s_0=s_0,
            optimal_length=info["optimal_length"],
            room_type=info["room_type"],
            inputs=seen,
        )
        # The lanes after the step: an episode that ended starts afresh (its LSTM carry,
        # previous action probabilities and step count zeroed).
        probs = distributions.probs(logits)
        if not carries_gradient:
            probs = jax.lax.stop_gradient(probs)
        next_actor = ActorState(
            env_state=env_state,
            obs=obs,
            lstm=reset_carry(done, lstm),
            prev_probs=jnp.where(done[:, None], 0.0, probs),
            imagined=imagined,
            s_0=s_0,
            episode_step=jnp.where(done, 0, actor.episode_step + 1),
            memory=memory,
            tracker=tracker,
        )
        return (next_actor, alive & ~done if options.whole_episodes else alive), out

    step_keys = jax.random.split(key, num_steps) if options.step_keys is None else options.step_keys
    alive = jnp.ones(lanes.shape, bool) if adapt.alive is None else adapt.alive
    (actor, _), out = jax.lax.scan(step, (actor, alive), (step_keys, adapt.gate_offsets))
    if options.whole_episodes:  # nothing is bootstrapped: every counted episode ended (or is cut by design)
        next_state = jnp.zeros_like(actor.s_0)
    else:  # s_T, for V(s*_T) at the cut (Eq. 8); the next window computes it again
        inputs = one_step(actor.obs, actor.prev_probs, encoder_imagined(nets, actor))
        next_state = nets.model.apply(
            params, actor.lstm, inputs, (actor.episode_step == 0)[None], kernels, method="encode"
        )[1][0]
    return actor, out, WindowEnd(jax.lax.stop_gradient(next_state), actor.episode_step)


def remember(actor: ActorState, s_t: chex.Array, lanes: chex.Array) -> Optional[chex.Array]:
    """The episode's states so far with s_t `[B, H]` at its position, for the attention
    critic of later windows (without gradient); None when nothing is carried across
    windows. lanes: `arange(B)`."""
    if actor.memory is None or not actor.memory.shape[1]:
        return actor.memory
    last = actor.memory.shape[1] - 1
    return actor.memory.at[lanes, jnp.minimum(actor.episode_step, last)].set(jax.lax.stop_gradient(s_t))


def rollout(
    nets: Networks,
    acting: AgentParams,
    env: BoundEnv,
    key,
    num_steps: int,
    options: ActOptions = ActOptions(whole_episodes=True, record_inputs=False),
    reset_keys: Optional[chex.Array] = None,
    act: Optional[Callable] = None,
) -> Trajectory:
    """One whole episode per lane from a fresh start, padded to `num_steps` (evaluation),
    with `acting.noise_variance` `[B]` (a scalar with `reset_keys`); `options`: greedy or
    sampled, inputs recorded or not (whole episodes always). The B lanes reset with
    `split(split(key)[0], B)` unless `reset_keys` `[B, ...]` are given. act: the base's
    window (`act_window`, the default, or `foresit_jax.maml.act`), with act_window's
    first seven arguments."""
    if acting.noise_variance is None:
        raise ValueError("rollout: give AgentParams.noise_variance, the evaluation's fixed variance")
    if act is None and nets.method.base_piece.adapts_in_episode:
        raise ValueError(
            f"rollout: method {nets.method.name!r} adapts its parameters inside each episode (the maml "
            "base): pass act=foresit_jax.maml.act (foresit_jax.evaluate.base_acting(config).act)"
        )
    noise_variance = jnp.asarray(acting.noise_variance, jnp.float32)
    if reset_keys is not None:
        num_lanes = reset_keys.shape[0]
    elif noise_variance.ndim == 1:
        num_lanes = noise_variance.shape[0]
    else:
        raise ValueError("rollout: give noise_variance with one entry per lane, or the lanes' reset_keys")
    acting = acting._replace(noise_variance=jnp.broadcast_to(noise_variance, (num_lanes,)))
    k_start, k_act = jax.random.split(key)
    actor = start(nets, k_start, env, num_lanes, reset_keys=reset_keys)
    options = options._replace(whole_episodes=True)
    _, traj, _ = (act or act_window)(nets, acting, env, actor, k_act, num_steps, options)
    return traj
