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
What i_tau is, and the tracker, are imagination's (`foresit_jax.imagination.at_step`,
`record_outcomes`, on the `ImaginationCarry` inside the agent's carry, `AgentCarry`); a
step here is `agent_step` (encode, `imagination.at_step`, the policy's logits), the
environment's step, then `advance` (the agent's carry after it).

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

from typing import Any, Callable, NamedTuple, Optional

import chex
import jax
import jax.numpy as jnp
from flax import struct

import envs.metrics
from foresit_jax import distributions, imagination
from foresit_jax.lstm import LowRankUpdate, LSTMCarry, initial_carry, reset_carry
from foresit_jax.networks import ActorCritic, Networks, one_step


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


class AgentCarry(NamedTuple):
    """What the agent carries per lane from one step to the next (leaves `[B, ...]`): what
    acting's window, the step-by-step policy (`foresit_jax.policy`) and the maml base carry
    alike. `advance` writes it after a step."""

    lstm: LSTMCarry  # (c, h) [B, H] each; zeros when a new episode begins
    prev_probs: chex.Array  # [B, A] previous action probabilities (zeros at an episode start)
    episode_step: chex.Array  # [B] int32 index of the next state in its episode (0: new episode)
    imagination: imagination.ImaginationCarry  # i_tau, s_0 and the success tracker (rho)


class ActorState(NamedTuple):
    """What each lane carries from one window to the next: the environment's state and
    observation, the agent's carry, and the attention critic's memory; leaves `[B, ...]`."""

    env_state: Any  # the environment's state (opaque to the agent)
    obs: Any  # observation dict to act on next, leaves [B, ...]
    agent: AgentCarry
    memory: Optional[chex.Array]  # [B, M, H] the running episode's states so far (attention critic; else None)


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
    memory = jnp.zeros((num_lanes, memory_size, cfg.hidden_size), jnp.float32) if memory_size else None
    return ActorState(env_state, obs, agent_carry(nets, num_lanes, tracker), memory)


def agent_carry(nets: Networks, num_lanes: int, tracker=None) -> AgentCarry:
    """The agent's carry before any step of `num_lanes` lanes: zeros, and fresh success
    trackers unless `tracker` (`[B, window]`) is kept."""
    cfg = nets.config
    return AgentCarry(
        lstm=initial_carry((num_lanes,), cfg.hidden_size),
        prev_probs=jnp.zeros((num_lanes, cfg.num_actions), jnp.float32),
        episode_step=jnp.zeros((num_lanes,), jnp.int32),
        imagination=imagination.carry_init(num_lanes, cfg.hidden_size, cfg.success_window, tracker),
    )


def acting_env(nets: Networks, env: BoundEnv) -> BoundEnv:
    """The environment `nets` acts in: `env` itself, or `env` wrapped to carry what its
    imagination reads (the goal view, a cue: `imagination.acting_env`)."""
    wrapped = imagination.acting_env(nets.imagination, env.env)
    return env if wrapped is env.env else BoundEnv(wrapped, env.params)


class StepOut(NamedTuple):
    """The agent's half of one step (`agent_step`), leaves `[B, ...]`."""

    lstm: LSTMCarry  # the LSTM's carry after the step
    state: chex.Array  # [B, H] s_t
    logits: chex.Array  # [B, A]
    imagined: chex.Array  # [B, H] i_tau given to the policy (the step's)
    imagination: imagination.ImaginationCarry  # imagination's carry after the step
    encoder_imagined: Optional[chex.Array]  # [B, H] the i_tau the encoder saw; None unless it reads one


def agent_step(
    nets: Networks, acting: AgentParams, kernels, agent: AgentCarry, obs, key: chex.PRNGKey, gate_offset
) -> StepOut:
    """The agent's half of a step: encode at T = 1, i_tau (`imagination.at_step`), then the
    policy's logits. `key`: i_tau's noise. Acting's window (`act_window`), the step-by-step
    policy (`foresit_jax.policy`) and the maml base's replayed segment run it, so they compute
    alike."""
    first = agent.episode_step == 0  # [B]
    seen_imagined = imagination.encoder_input(nets.imagination, agent.imagination, agent.episode_step, obs)
    offsets = None if gate_offset is None else gate_offset[None]
    lstm, states = nets.model.apply(
        acting.params,
        agent.lstm,
        one_step(obs, agent.prev_probs, seen_imagined),
        first[None],
        kernels,
        offsets,
        method=ActorCritic.encode,
    )
    s_t = states[0]
    imagined, carry = imagination.at_step(
        nets.imagination, acting, kernels, agent.imagination, s_t, agent.episode_step, obs, key
    )
    logits = nets.model.apply(acting.params, s_t, imagined, method=ActorCritic.policy_logits)
    return StepOut(lstm, s_t, logits, imagined, carry, seen_imagined)


def advance(nets: Networks, agent: AgentCarry, out: StepOut, done: Optional[chex.Array] = None) -> AgentCarry:
    """The agent's carry after a step (the bookkeeping written once, for acting, the
    step-by-step policy and the maml base): the step's LSTM carry and imagination, its
    action probabilities (without gradient unless the method carries it), the next
    position. `done` `[B]`: the lanes whose episode ended at the step start afresh (LSTM
    carry, previous action probabilities and step count zeroed); None: no episode ended
    (the step-by-step policy resets at the next step's `first` instead)."""
    probs = distributions.probs(out.logits)
    if not nets.method.action_probs_carry_gradient:
        probs = jax.lax.stop_gradient(probs)
    if done is None:
        return AgentCarry(out.lstm, probs, agent.episode_step + 1, out.imagination)
    return AgentCarry(
        lstm=reset_carry(done, out.lstm),
        prev_probs=jnp.where(done[:, None], 0.0, probs),
        episode_step=jnp.where(done, 0, agent.episode_step + 1),
        imagination=out.imagination,
    )


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
    is the agent's (`agent_step`: `ActorCritic.encode` at T = 1, i_tau, `ActorCritic.policy_logits`),
    then the environment's. `adapt`: what the maml base's inner loop gives a window
    (`Adaptation`; the default: nothing)."""
    if adapt.alive is None and nets.method.base_piece.adapts_in_episode:
        raise ValueError(
            f"act_window plays one parameter set, and method {nets.method.name!r} adapts its parameters "
            "inside each episode (the maml base): use foresit_jax.maml.act (Trainer.act_window, "
            "foresit_jax.evaluate.base_acting(config).act)"
        )
    params, lanes = acting.params, jnp.arange(actor.agent.episode_step.shape[0])
    env = acting_env(nets, env)
    kernels = nets.lstm_kernels(params, adapt.lstm_update)  # once, outside the loop
    in_head = nets.imagination_in_head

    def step(carry, xs):
        actor, alive = carry
        key, gate_offset = xs
        k_imag, k_act, k_env = jax.random.split(key, 3)
        agent = actor.agent
        out = agent_step(nets, acting, kernels, agent, actor.obs, k_imag, gate_offset)
        action = distributions.greedy(out.logits) if options.greedy else distributions.sample(k_act, out.logits)
        memory = remember(actor, out.state, lanes)
        obs, env_state, reward, term, trunc, info = env.step(
            jax.random.split(k_env, lanes.shape[0]), actor.env_state, action
        )
        done = term | trunc
        out = out._replace(imagination=imagination.record_outcomes(out.imagination, info["success"], done & alive))
        seen = None
        if options.record_inputs:
            policy_input = out.imagined if in_head else None
            seen = StepInputs(actor.obs, agent.prev_probs, policy_input, out.encoder_imagined)
        record = Trajectory(
            states=out.state,
            logits=out.logits,
            actions=action,
            rewards=reward,
            terminated=term,
            truncated=trunc,
            valid=alive,
            success=info["success"] & alive,
            episode_step=agent.episode_step,
            s_0=out.imagination.s_0,
            optimal_length=info["optimal_length"],
            room_type=info["room_type"],
            inputs=seen,
        )
        next_actor = ActorState(env_state, obs, advance(nets, agent, out, done), memory)
        return (next_actor, alive & ~done if options.whole_episodes else alive), record

    step_keys = jax.random.split(key, num_steps) if options.step_keys is None else options.step_keys
    alive = jnp.ones(lanes.shape, bool) if adapt.alive is None else adapt.alive
    (actor, _), out = jax.lax.scan(step, (actor, alive), (step_keys, adapt.gate_offsets))
    agent = actor.agent
    if options.whole_episodes:  # nothing is bootstrapped: every counted episode ended (or is cut by design)
        next_state = jnp.zeros_like(agent.imagination.s_0)
    else:  # s_T, for V(s*_T) at the cut (Eq. 8); the next window computes it again
        seen = imagination.encoder_input(nets.imagination, agent.imagination, agent.episode_step, actor.obs)
        first = (agent.episode_step == 0)[None]
        inputs = one_step(actor.obs, agent.prev_probs, seen)
        next_state = nets.model.apply(params, agent.lstm, inputs, first, kernels, method=ActorCritic.encode)[1][0]
    return actor, out, WindowEnd(jax.lax.stop_gradient(next_state), agent.episode_step)


def remember(actor: ActorState, s_t: chex.Array, lanes: chex.Array) -> Optional[chex.Array]:
    """The episode's states so far with s_t `[B, H]` at its position, for the attention
    critic of later windows (without gradient); None when nothing is carried across
    windows. lanes: `arange(B)`."""
    if actor.memory is None or not actor.memory.shape[1]:
        return actor.memory
    last = actor.memory.shape[1] - 1
    return actor.memory.at[lanes, jnp.minimum(actor.agent.episode_step, last)].set(jax.lax.stop_gradient(s_t))


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
