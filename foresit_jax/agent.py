"""The acting agent: one rollout function shared by training and evaluation.

An `Agent` ties the networks of a `Config` together (encoder + policy + critic under one
parameter tree, theta and omega; f_w under its own tree, w) and its method's pieces
(`foresit_jax.methods`), and drives any environment with the GridNav API (``reset`` /
``step`` vmapped over lanes; per-episode facts read from the step's ``info``:
``success``, ``optimal_length``, ``room_type``), never from the environment's state.

Acting takes three records: `AgentParams` (what acts: theta/omega, f_w's w, the noise
variance), `BoundEnv` (the environment bound to its parameters once) and `ActOptions` (how:
greedy or sampled, packed windows or whole episodes, whether to record the inputs).
`act` runs every lane for a window of `num_steps` steps from an `ActorState` and returns
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
"""

from __future__ import annotations

import functools
from typing import Any, Callable, NamedTuple, Optional

import chex
import jax
import jax.numpy as jnp
from flax import struct

import envs.metrics
from envs.wrappers import GoalViewWrapper
from foresit_jax import distributions, imagination
from foresit_jax.config import Config
from foresit_jax.lstm import LowRankUpdate, LSTMCarry, LSTMKernels, initial_carry, lstm_step, reset_carry
from foresit_jax.methods import BaseFunctions
from foresit_jax.networks import ActorCritic, CriticOutput, ImaginationNet, window_attention_mask


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
    `Agent.act_window` records one, `[B, ...]`; the scan stacks them). What follows the
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


class Agent:
    """Networks, method pieces and acting for one `Config`."""

    def __init__(self, config: Config):
        self.config = config
        self.method = config.pieces
        self.imagination_variant = self.method.imagination_variant
        self.model = ActorCritic(
            # ORG's object-relation graph over the `org` setup's detector features (None: none).
            object_graph=self.method.encoder_piece.object_graph(),
            # SAVN's learned interaction loss (the maml base; params["params"]["learned_loss"]).
            learned_loss=self.method.base_piece.learned_loss(config),
            num_actions=config.num_actions,
            hidden_size=config.hidden_size,
            use_imagination=self.imagination_variant.uses_imagination,
            attention_critic=self.method.attention_critic,
            attention_size=config.attention_size,
            value_hidden=config.value_hidden,
            linear_value_head=config.value_head == "linear",
            imagination_input=config.imagination_input,
            zero_value_init=config.attention_value_init == "zeros",
            key_gradient=config.attention_key_gradient == "full",
        )
        self.imagination_net = ImaginationNet(config.imagination_layer_sizes)
        # Where i_tau enters (Config.imagination_input), as the network decides it.
        self.imagination_in_encoder = self.model.imagination_in_encoder
        self.imagination_in_head = self.imagination_variant.uses_imagination and not self.imagination_in_encoder
        # What the base's `act` uses: these pure functions and its settings (methods.Base).
        self.base_functions = BaseFunctions(self.act_window, self.lstm_inputs, self.interaction_loss)
        self.base_settings = self.method.base_piece.settings(config)

    # ------------------------------------------------------------------ init
    def init(self, key: chex.PRNGKey, obs: dict) -> tuple[Any, Any]:
        """(theta/omega params, f_w params) from one unbatched observation."""
        k_model, k_imag = jax.random.split(key)
        hidden = self.config.hidden_size
        carry = initial_carry((), hidden)
        probs = jnp.zeros((self.config.num_actions,), jnp.float32)
        imagined = jnp.zeros((hidden,), jnp.float32) if self.imagination_variant.uses_imagination else None
        params = self.model.init(k_model, carry, obs, probs, imagined)
        w_params = self.imagination_net.init(k_imag, jnp.zeros((hidden,)), obs["target"])
        return params, w_params

    def interaction_loss(self, params, inputs: chex.Array) -> chex.Array:
        """The maml base's learned loss L_phi of one segment `[segment, H + A]` (scalar)."""
        return self.model.apply(params, inputs, method=ActorCritic.interaction_loss)

    def imagine(self, w_params, s_0: chex.Array, goal: chex.Array) -> chex.Array:
        """f_w([s_0 : g_tau]) `[..., H]`."""
        return self.imagination_net.apply(w_params, s_0, goal)

    def start(
        self, key, env: BoundEnv, num_lanes: int, memory_size: int = 0, tracker=None, reset_keys=None
    ) -> ActorState:
        """Every lane at the start of a fresh episode. memory_size: states of an episode
        the attention critic can remember across windows (the training time limit; 0 when
        nothing is carried across windows: `memory` is then None). tracker: per-lane success trackers to keep
        (fresh ones by default). reset_keys: `[num_lanes, ...]` the lanes' reset keys
        (default: `split(key, num_lanes)`)."""
        if isinstance(num_lanes, bool) or not isinstance(num_lanes, int) or num_lanes < 1:
            raise ValueError(f"num_lanes must be a positive int, got {num_lanes!r}")
        cfg = self.config
        env = self.acting_env(env)
        reset_keys = jax.random.split(key, num_lanes) if reset_keys is None else reset_keys
        obs, env_state = env.reset(reset_keys)
        hidden = cfg.hidden_size
        zeros = jnp.zeros((num_lanes, hidden), jnp.float32)
        if tracker is None:
            one = imagination.tracker_init(cfg.success_window)
            tracker = jax.tree.map(lambda x: jnp.broadcast_to(x, (num_lanes,) + x.shape), one)
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

    def acting_env(self, env: BoundEnv) -> BoundEnv:
        """The environment this agent acts in: `env` itself, or, for an imagination that
        reads the goal view (the privileged `oracle`), `env` wrapped to carry it
        (`envs.wrappers.GoalViewWrapper`; built for that method alone, so no other
        program changes)."""
        if not self.imagination_variant.reads_goal_view or isinstance(env.env, GoalViewWrapper):
            return env
        return BoundEnv(GoalViewWrapper(env.env), env.params)

    # ------------------------------------------------------------------ acting
    def goal_latent(self, params, kernels: LSTMKernels, obs) -> chex.Array:
        """The agent's own latent of its episodes' goal views `[B, H]` (privileged; the
        `oracle` imagination's i_tau before noise): the encoder and one LSTM step from a
        fresh carry (zero carry and previous action probabilities, as at an episode's
        first step) on `obs`'s goal view (`GoalViewWrapper.goal_of`), under `kernels`."""
        lanes = obs["target"].shape[:-1]
        hidden = self.config.hidden_size
        probs = jnp.zeros(lanes + (self.config.num_actions,), jnp.float32)
        encoder_imagined = jnp.zeros(lanes + (hidden,), jnp.float32) if self.imagination_in_encoder else None
        gates = self.input_gates(params, GoalViewWrapper.goal_of(obs), probs, kernels, encoder_imagined)
        _, latent = lstm_step(kernels, initial_carry(lanes, hidden), gates)
        return latent

    def lstm_inputs(self, params, obs, prev_action_probs, encoder_imagined=None):
        """The encoder's output, the LSTM's input x_t `[..., F]` (encoder_imagined: the
        encoder's i_tau `[..., H]`, with `imagination_in_encoder`)."""
        return self.model.apply(params, obs, prev_action_probs, encoder_imagined, method=ActorCritic.encoder_features)

    def lstm_kernels(self, params, update: Optional[LowRankUpdate] = None) -> LSTMKernels:
        """The encoder LSTM's kernels in `params`, with a low-rank `update` or None
        (`ActorCritic.lstm_kernels`)."""
        return self.model.apply(params, update, method=ActorCritic.lstm_kernels)

    def input_gates(self, params, obs, prev_action_probs, kernels=None, encoder_imagined=None):
        """The encoder up to the LSTM's input gates `[..., 4H]`: everything of a step
        that does not depend on the LSTM carry (`ActorCritic.input_gates`)."""
        kernels = self.lstm_kernels(params) if kernels is None else kernels
        return self.model.apply(params, obs, prev_action_probs, encoder_imagined, kernels,
                                method=ActorCritic.input_gates)  # fmt: skip

    def encoder_imagined(self, actor: ActorState) -> Optional[chex.Array]:
        """The i_tau the encoder sees at the lanes' next step `[B, H]`: the running episode's,
        zeros at an episode's first step (i_tau is imagined from that step's output);
        None unless i_tau enters the encoder."""
        if not self.imagination_in_encoder:
            return None
        return jnp.where((actor.episode_step == 0)[:, None], 0.0, actor.imagined)

    def act(
        self, acting: AgentParams, env: BoundEnv, actor: ActorState, key: chex.PRNGKey, num_steps: int,
        options: ActOptions = ActOptions(),
    ) -> tuple[ActorState, Trajectory, WindowEnd]:  # fmt: skip
        """Run every lane `num_steps` steps from `actor` (see the module docstring); returns
        (the actor state after the window, the window's Trajectory, what follows it).

        How a window is acted is the base's (`methods.Base.act`): the a3c base runs
        `act_window` under one parameter set; the maml base adapts each lane's parameters
        inside its episode (`foresit_jax.maml.adaptive_act`): whole episodes only, in
        training and evaluation.
        """
        return self.method.base_piece.act(self.base_functions, self.base_settings, acting, env, actor, key, num_steps,
                                          options)  # fmt: skip

    def imagined_at_step(self, acting: AgentParams, actor: ActorState, s_t: chex.Array,
                         key: chex.PRNGKey, goal_latent: Optional[Callable[[], chex.Array]] = None) -> chex.Array:  # fmt: skip
        """i_tau for a step `[B, H]` (Eq. 6-7): renewed where the ImaginationVariant piece says (an
        episode's first step; every K steps for `int`) from s_t (= s_0 at the first step)
        by f_w (`acting.imagination_params`), with noise of each lane's variance
        (`acting.noise_variance` `[B]`, or Eq. 7 from its success tracker), else the
        running episode's. Unchanged without imagination. goal_latent: `() -> [B, H]`,
        the goal view's latent (`goal_latent`), for an imagination that reads it (called
        only where i_tau is renewed)."""
        cfg, variant = self.config, self.imagination_variant  # the method's ImaginationVariant piece
        if not variant.uses_imagination:
            return actor.imagined
        noise_variance = acting.noise_variance
        if noise_variance is None:
            noise_variance = imagination.noise_variance(jax.vmap(imagination.success_rate)(actor.tracker), cfg.sigma2_max)
        renew = variant.renews(actor.episode_step, cfg.int_interval)  # [B]
        goal = actor.obs["target"]

        def renewed():
            mask = renew[:, None]  # [B, 1], before the imagination (the order of the lowered program's ops)
            return jnp.where(mask, variant.imagine(self.imagine, acting.imagination_params, s_t, goal, key, noise_variance,
                                                    cfg.rnd_variance, cfg.imagination_noise == "input",
                                                    None if goal_latent is None else goal_latent()),
                             actor.imagined)  # fmt: skip

        return jax.lax.cond(jnp.any(renew), renewed, lambda: actor.imagined)

    def act_window(
        self, acting: AgentParams, env: BoundEnv, actor: ActorState, key: chex.PRNGKey, num_steps: int,
        options: ActOptions = ActOptions(), *, alive: Optional[chex.Array] = None,
        lstm_update: Optional[LowRankUpdate] = None, gate_offsets: Optional[chex.Array] = None,
    ) -> tuple[ActorState, Trajectory, WindowEnd]:  # fmt: skip
        """`act` under one parameter set for the whole window (every base's step).
        alive: `[B]` bool, with `whole_episodes`, which lanes' counted episode is still
        running at the window's start (default: all; a window that continues an earlier
        one of the same whole-episode rollout passes what that one left).
        lstm_update: a low-rank change of the LSTM's kernels (the maml base's adapted
          kernels, `foresit_jax.maml`); gate_offsets: `[num_steps, B, 4H]` added to each
          step's gate pre-activations (zeros whose gradient is the pre-activations')."""
        params, lanes = acting.params, jnp.arange(actor.episode_step.shape[0])
        env = self.acting_env(env)
        kernels = self.lstm_kernels(params, lstm_update)  # once, outside the loop

        def step(carry, xs):
            actor, alive = carry
            key, gate_offset = xs
            k_imag, k_act, k_env = jax.random.split(key, 3)
            first = actor.episode_step == 0  # [B]
            encoder_imagined = self.encoder_imagined(actor)  # [B, H] or None
            input_gates = self.input_gates(params, actor.obs, actor.prev_probs, kernels, encoder_imagined)  # [B, 4H]
            if gate_offset is not None:
                input_gates = input_gates + gate_offset
            lstm, s_t = lstm_step(kernels, actor.lstm, input_gates)
            s_0 = jnp.where(first[:, None], s_t, actor.s_0)
            goal_latent = None  # the oracle's: computed only where i_tau is renewed
            if self.imagination_variant.reads_goal_view:
                goal_latent = functools.partial(self.goal_latent, params, kernels, actor.obs)
            imagined = self.imagined_at_step(acting, actor, s_t, k_imag, goal_latent)  # [B, H]
            policy_input = imagined if self.imagination_in_head else None
            logits = self.model.apply(params, s_t, policy_input, method=ActorCritic.policy_logits)
            action = distributions.greedy(logits) if options.greedy else distributions.sample(k_act, logits)
            memory = self.remember(actor, s_t, lanes)
            obs, env_state, reward, term, trunc, info = env.step(
                jax.random.split(k_env, lanes.shape[0]), actor.env_state, action
            )
            done = term | trunc
            tracker = jax.vmap(imagination.tracker_update)(actor.tracker, info["success"], done & alive)
            seen = StepInputs(actor.obs, actor.prev_probs, policy_input, encoder_imagined) if options.record_inputs else None
            out = Trajectory(
                states=s_t, logits=logits, actions=action, rewards=reward, terminated=term, truncated=trunc,
                valid=alive, success=info["success"] & alive, episode_step=actor.episode_step, s_0=s_0,
                optimal_length=info["optimal_length"], room_type=info["room_type"], inputs=seen,
            )  # fmt: skip
            next_actor = self.next_actor(actor, done, lstm, logits, env_state, obs, imagined, s_0, memory, tracker)
            return (next_actor, alive & ~done if options.whole_episodes else alive), out

        step_keys = jax.random.split(key, num_steps) if options.step_keys is None else options.step_keys
        alive = jnp.ones(lanes.shape, bool) if alive is None else alive
        (actor, _), out = jax.lax.scan(step, (actor, alive), (step_keys, gate_offsets))
        if options.whole_episodes:  # nothing is bootstrapped: every counted episode ended (or is cut by design)
            next_state = jnp.zeros_like(actor.s_0)
        else:  # s_T, for V(s*_T) at the cut (Eq. 8); the next window computes it again
            gates = self.input_gates(params, actor.obs, actor.prev_probs, kernels, self.encoder_imagined(actor))
            _, next_state = lstm_step(kernels, actor.lstm, gates)
        return actor, out, WindowEnd(jax.lax.stop_gradient(next_state), actor.episode_step)

    @staticmethod
    def remember(actor: ActorState, s_t: chex.Array, lanes: chex.Array) -> Optional[chex.Array]:
        """The episode's states so far with s_t `[B, H]` at its position, for the attention
        critic of later windows (without gradient); None when nothing is carried across
        windows. lanes: `arange(B)`."""
        if actor.memory is None or not actor.memory.shape[1]:
            return actor.memory
        last = actor.memory.shape[1] - 1
        return actor.memory.at[lanes, jnp.minimum(actor.episode_step, last)].set(jax.lax.stop_gradient(s_t))

    def next_actor(self, actor: ActorState, done, lstm, logits, env_state, obs, imagined, s_0, memory,
                   tracker) -> ActorState:  # fmt: skip
        """The lanes after a step: an episode that ended (`done` `[B]`) starts afresh (its
        LSTM carry, previous action probabilities and step count zeroed)."""
        probs = distributions.probs(logits)
        if not self.method.action_probs_carry_gradient:
            probs = jax.lax.stop_gradient(probs)
        return ActorState(
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

    def rollout(
        self, acting: AgentParams, env: BoundEnv, key, num_steps: int, greedy: bool = False,
        record_inputs: bool = False, num_lanes: Optional[int] = None, reset_keys: Optional[chex.Array] = None,
    ) -> Trajectory:  # fmt: skip
        """One whole episode per lane from a fresh start, padded to `num_steps`
        (evaluation), with `acting.noise_variance` `[B]` (or a scalar with `num_lanes`).
        The lanes reset with `split(split(key)[0], B)` unless `reset_keys` `[B, ...]` are given."""
        if acting.noise_variance is None:
            raise ValueError("rollout: give AgentParams.noise_variance, the evaluation's fixed variance")
        noise_variance = jnp.asarray(acting.noise_variance, jnp.float32)
        if num_lanes is None:
            if noise_variance.ndim != 1:
                raise ValueError("rollout: give num_lanes, or noise_variance with one entry per lane")
            num_lanes = noise_variance.shape[0]
        acting = acting._replace(noise_variance=jnp.broadcast_to(noise_variance, (num_lanes,)))
        k_start, k_act = jax.random.split(key)
        actor = self.start(k_start, env, num_lanes, reset_keys=reset_keys)
        options = ActOptions(greedy=greedy, whole_episodes=True, record_inputs=record_inputs)
        _, traj, _ = self.act(acting, env, actor, k_act, num_steps, options)
        return traj

    # ------------------------------------------------------------------ critic
    def critic(self, params, traj: Trajectory, end: WindowEnd,
               memory: Optional[chex.Array]) -> tuple[CriticOutput, chex.Array]:  # fmt: skip
        """The critic over a window, the state after it (`end`) included: (CriticOutput with
        value `[T + 1, B]` (row T: V(s*_T), the bootstrap), alpha `[B, T + 1, M + T + 1]`
        or None; keys `[B, M + T + 1, H]`, what alpha weighs).

        Each step attends over the states of its own episode up to itself (Eq. 3-4):
        those of earlier windows (`memory` `[B, M, H]`, the ActorState's at the window's
        start, without gradient; None: no memory) and the window's."""
        if memory is None:
            memory = jnp.zeros((traj.states.shape[1], 0, traj.states.shape[2]), traj.states.dtype)
        states = jnp.concatenate([traj.states, end.state[None]], axis=0)  # [T + 1, B, H]
        steps = jnp.concatenate([traj.episode_step, end.episode_step[None]], axis=0)  # [T + 1, B]
        states, steps = jnp.swapaxes(states, 0, 1), jnp.swapaxes(steps, 0, 1)  # [B, T + 1, ...]
        keys = jnp.concatenate([jax.lax.stop_gradient(memory), states], axis=1)  # [B, M + T + 1, H]
        mask = window_attention_mask(steps, memory.shape[1])
        out = self.model.apply(
            params, states, jnp.ones(steps.shape, bool), keys, mask, steps, method=ActorCritic.critic
        )
        return out._replace(value=jnp.swapaxes(out.value, 0, 1)), keys
