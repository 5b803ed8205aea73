"""Synchronous batched actor-critic standing in for A3C (PureJaxRL shape).

One update = every lane acts for a window of `num_steps` steps (the base's window:
`rollout.act_window`, or `maml.act` where the parameters adapt inside episodes; with
`Config.rollout='packed'` lanes never idle: episodes follow one another and an episode
cut at the window's edge continues in the next update, its cut bootstrapped with
V(s*_T), Eq. 8), then one gradient step on the mean A3C loss over the window (Eq. 8-9),
then the ForeSIT bookkeeping of Algorithm 1 (`imagination.learn`, the update's last call)
for every episode that ended in the window, in time order: a successful one adds (s_0, g_tau, ŝ_tau) to its lane's buffer (ŝ_tau:
the argmax of its last step's attention over all its states, earlier windows' included),
and full buffers train the shared f_w and are emptied. Each lane's success tracker
(rho, which sets the imagination noise of Eq. 7) is updated while acting.

    trainer = make_trainer(config)
    state = trainer.init(key)
    state, metrics = trainer.run(state, trainer.env_params, num_updates)  # jittable
    train = make_train(config)                      # PureJaxRL: one jittable function
    final_state, metrics = jax.jit(jax.vmap(train))(keys)    # a seed sweep in one program

The file reads as one update does: the records, the losses (returns, advantages, Eq. 8-9),
the replay and the critic of a window, the Trainer's update and run.

Metrics are reduced per update inside the scan (scalars per update, nothing grows with
the number of environment steps). `frames/useful` counts the steps that enter the loss,
`frames/stepped` every environment step taken (they differ only with whole-episode
updates, whose padding is stepped and masked away).
"""

from __future__ import annotations

import functools
from typing import Any, Callable, Mapping, NamedTuple

import chex
import jax
import jax.numpy as jnp
import optax

import envs
from foresit_jax import distributions, imagination, maml, rollout
from foresit_jax.config import Config
from foresit_jax.lstm import LSTMCarry
from foresit_jax.networks import ActorCritic, CriticOutput, EncoderInputs, Networks, build, window_attention_mask
from foresit_jax.rollout import ActOptions, ActorState, AgentParams, BoundEnv, Trajectory, WindowEnd, ended_episodes


# How often `Trainer.run` reports progress to the host, in updates: a host callback after
# every update slows training (docs/design.md, 'Speed'), and every 10th is often enough for
# a progress display.
PROGRESS_EVERY = 10


class RunnerState(NamedTuple):
    """Everything a training run carries from one update to the next."""

    params: Any  # theta and omega (encoder, policy, critic)
    opt_state: Any  # Adam state of params
    imagination_params: Any  # w, the shared f_w
    buffers: imagination.ReplayBuffer  # per lane, leaves [B, M, ...]
    actor: ActorState  # per lane: env, LSTM carry, running episode (tracker included)
    key: chex.PRNGKey
    update: chex.Array  # int32 [] updates done
    targets: Any = None  # the auxiliary target's head and its optimiser (`imagination.TargetState`); None: no target


class WindowResult(NamedTuple):
    """What `Trainer.loss_and_grad` returns beside the loss (the aux of its value_and_grad)."""

    next_actor: ActorState  # the lanes after the window
    traj: Trajectory  # the window (states and logits differentiable in the params, replayed)
    alpha: Any  # [B, T + 1, K] the critic's attention rows, or None (plain critic)
    key_states: chex.Array  # [B, K, H] the states alpha weighs (the attention's keys)
    metrics: dict  # the loss's scalars


# The losses: return/advantage estimation and the A3C objective of the paper (Eq. 5,
# Eq. 8-9); f_w's smooth-L1 is `imagination.smooth_l1`.
#
# Conventions (as rlax, but time-major and batch-agnostic): every per-step array is
# `[T, ...]` with time first; any trailing batch shape (`[T]`, `[T, B]`) works because the
# recursions `lax.scan` over the leading axis only. `r_t` is the reward received after
# acting at step t, `v_t` the value estimate of the state at step t, `discount_t` the
# discount applied to whatever follows step t (0 where the episode ended there).
#
# Episode ends inside a window. One training update runs every env lane for a window of
# `T` steps: with packed windows (the default) episodes follow one another and every step is
# valid; with whole-episode windows (`Config.rollout='episodes'`, and evaluation) each lane
# plays one episode padded to `T` steps, and `valid_t` is 1 for the steps of that episode
# (including its last one) and 0 for the padding after it. Three rules, in
# `episode_discounts`:
# * `terminated_t` (the agent chose Done): nothing follows, no bootstrap.
# * `truncated_t` (time limit): also no bootstrap, as in SAVN (its `a3c_loss` sets R = 0
#   whenever the episode is over, time limit included); docs/design.md, one update's step 4:
#   "Done and the time limit bootstrap nothing".
# * padding: a padding step neither contributes (outputs are zeroed) nor is bootstrapped
#   from (the step before it gets discount 0 even without a done flag).
#
# Only when the last step of the rollout is valid and the episode is still running does
# `bootstrap_value` (the value of the state after the rollout) enter.


def episode_discounts(
    terminated_t: chex.Array,
    truncated_t: chex.Array,
    valid_t: chex.Array,
    gamma: float,
) -> chex.Array:
    """Per-step discounts `[T, ...]` for a padded rollout.

    discount_t = gamma * valid_t * (1 - (terminated_t | truncated_t)) * valid_{t+1},
    with valid_T := 1 (a running episode at the rollout's end is bootstrapped).
    """
    chex.assert_equal_shape([terminated_t, truncated_t, valid_t])
    ended_t = jnp.logical_or(terminated_t.astype(bool), truncated_t.astype(bool))
    valid = valid_t.astype(bool)
    valid_tp1 = jnp.concatenate([valid[1:], jnp.ones_like(valid[:1])], axis=0)
    keep = valid & ~ended_t & valid_tp1
    return gamma * keep.astype(jnp.float32)


def discounted_returns(r_t: chex.Array, discount_t: chex.Array, bootstrap_value: chex.Array) -> chex.Array:
    """Discounted returns R_t = r_t + discount_t * R_{t+1}, R_T = bootstrap_value.

    Shapes: `r_t`, `discount_t` `[T, ...]`; `bootstrap_value` `[...]`. Returns `[T, ...]`.
    This is SAVN's value target R (Monte Carlo with bootstrap); it equals
    GAE(lambda=1) + v_t.
    """
    chex.assert_equal_shape([r_t, discount_t])
    chex.assert_equal_shape([r_t[0], bootstrap_value])

    def step(acc, inputs):
        r, discount = inputs
        acc = r + discount * acc
        return acc, acc

    _, returns = jax.lax.scan(step, bootstrap_value, (r_t, discount_t), reverse=True)
    return returns


def generalized_advantage_estimation(
    r_t: chex.Array,
    v_t: chex.Array,
    discount_t: chex.Array,
    bootstrap_value: chex.Array,
    lambda_: float,
) -> chex.Array:
    """GAE: A_t = delta_t + discount_t * lambda * A_{t+1}, A_T = 0, where
    delta_t = r_t + discount_t * v_{t+1} - v_t and v_T = bootstrap_value.

    Shapes: `r_t`, `v_t`, `discount_t` `[T, ...]`; `bootstrap_value` `[...]`.
    SAVN's `tau` is this `lambda_` (1.0 there).
    """
    chex.assert_equal_shape([r_t, v_t, discount_t])
    chex.assert_equal_shape([r_t[0], bootstrap_value])
    v_tp1 = jnp.concatenate([v_t[1:], bootstrap_value[None]], axis=0)  # [T, ...]
    delta_t = r_t + discount_t * v_tp1 - v_t  # [T, ...]

    def step(acc, inputs):
        delta, discount = inputs
        acc = delta + discount * lambda_ * acc
        return acc, acc

    _, advantages = jax.lax.scan(step, jnp.zeros_like(bootstrap_value), (delta_t, discount_t), reverse=True)
    return advantages


def advantages_and_returns(
    r_t: chex.Array,
    v_t: chex.Array,
    terminated_t: chex.Array,
    truncated_t: chex.Array,
    valid_t: chex.Array,
    bootstrap_value: chex.Array,
    gamma: float,
    lambda_: float,
) -> tuple[chex.Array, chex.Array]:
    """(advantage_t, return_t), both `[T, ...]` and zero on padding steps.

    The two A3C targets from one padded rollout: GAE(lambda) advantages for the policy
    and discounted returns for the value (Eq. 8-9). Inputs are treated as constants
    (`stop_gradient`), so `v_t` may come straight from the differentiated forward pass.
    """
    r_t, v_t, bootstrap_value = jax.lax.stop_gradient((r_t, v_t, bootstrap_value))
    valid = valid_t.astype(jnp.float32)
    discount_t = episode_discounts(terminated_t, truncated_t, valid_t, gamma)
    r_t = r_t * valid  # padding rewards never enter a recursion
    v_t = v_t * valid
    advantage_t = generalized_advantage_estimation(r_t, v_t, discount_t, bootstrap_value, lambda_)
    return_t = discounted_returns(r_t, discount_t, bootstrap_value)
    return advantage_t * valid, return_t * valid


def masked_mean(x: chex.Array, mask: chex.Array) -> chex.Array:
    """Mean of `x` over entries where `mask` is 1 (0.0 when the mask is empty)."""
    chex.assert_equal_shape([x, mask])
    mask = mask.astype(x.dtype)
    return jnp.sum(x * mask) / jnp.maximum(jnp.sum(mask), 1.0)


def masked_variance(x: chex.Array, mask: chex.Array) -> chex.Array:
    """Population variance of `x` over the entries where `mask` is 1 (0.0 when empty)."""
    mean = masked_mean(x, mask)
    return masked_mean((x - mean) ** 2, mask)


def explained_variance(v_t: chex.Array, return_t: chex.Array, mask: chex.Array) -> chex.Array:
    """1 - Var(R - v) / Var(R) over the masked entries: how much of the returns' spread
    the value baseline explains (1: all, 0: no better than their mean, < 0: worse);
    0.0 where the returns do not vary."""
    var_return = masked_variance(return_t, mask)
    ratio = masked_variance(return_t - v_t, mask) / jnp.maximum(var_return, 1e-8)
    return jnp.where(var_return > 1e-8, 1.0 - ratio, 0.0)


def a3c_loss(
    logits_t: chex.Array,
    a_t: chex.Array,
    v_t: chex.Array,
    advantage_t: chex.Array,
    return_t: chex.Array,
    valid_t: chex.Array,
    entropy_coef: float = 0.01,
    value_coef: float = 0.5,
) -> tuple[chex.Array, Mapping[str, chex.Array]]:
    """The A3C objective of Eq. 8-9 (Eq. 1-2 with V(s*_t) for ForeSIT).

    Args:
      logits_t: `[T, ..., A]` policy logits (differentiated).
      a_t: `[T, ...]` int actions taken.
      v_t: `[T, ...]` value estimates V(s*_t) (or V(s_t)), differentiated.
      advantage_t, return_t: `[T, ...]` targets from `advantages_and_returns`
        (stop-gradient is applied here too).
      valid_t: `[T, ...]` 1 on real steps, 0 on padding.

    Per step: policy term -log pi(a_t) * A_t - entropy_coef * H(pi_t); value term
    0.5 * (v_t - R_t)**2. Each is a masked mean over valid steps (SAVN sums over one
    episode; a mean keeps the scale independent of T and of the number of lanes).
    total = policy + value_coef * value.

    Returns (total_loss scalar, metrics dict of scalars).
    """
    chex.assert_equal_shape([a_t, v_t, advantage_t, return_t, valid_t])
    chex.assert_equal_shape_prefix([logits_t, a_t], a_t.ndim)
    advantage_t, return_t = jax.lax.stop_gradient((advantage_t, return_t))
    logp_t = distributions.log_prob(logits_t, a_t)  # [T, ...]
    entropy_t = distributions.entropy(logits_t)  # [T, ...]

    policy_gradient_loss = masked_mean(-logp_t * advantage_t, valid_t)
    entropy = masked_mean(entropy_t, valid_t)
    policy_loss = policy_gradient_loss - entropy_coef * entropy
    value_loss = masked_mean(0.5 * (v_t - return_t) ** 2, valid_t)
    total_loss = policy_loss + value_coef * value_loss

    metrics = {
        "losses/total_loss": total_loss,
        "losses/policy_loss": policy_loss,
        "losses/policy_gradient_loss": policy_gradient_loss,
        "losses/value_loss": value_loss,
        "losses/entropy": entropy,
        "losses/advantage_mean": masked_mean(advantage_t, valid_t),
        "losses/advantage_std": jnp.sqrt(masked_variance(advantage_t, valid_t)),
        "losses/explained_variance": explained_variance(jax.lax.stop_gradient(v_t), return_t, valid_t),
        "losses/value_mean": masked_mean(jax.lax.stop_gradient(v_t), valid_t),
        "losses/return_mean": masked_mean(return_t, valid_t),
        "losses/num_valid_steps": jnp.sum(valid_t.astype(jnp.float32)),
    }
    return total_loss, metrics


def make_env(config: Config, split: str = "train", room_types=None, training: bool | None = None):
    """The environment of a config (foresit_jax sees envs only through its public API)."""
    rooms = room_types if room_types is not None else (config.room_types or None)
    env, params = envs.make(
        "GridNav-v0",
        setup=config.setup,
        split=split,
        room_types=rooms,
        training=training,
        layout=config.layout,
        priors=config.priors,
        perception_range=config.perception_range,
    )
    return env, params.replace(progress_reward=config.progress_reward)


# ---------------------------------------------------------------------- the loss's inputs
# The replay gradient. Acting runs without gradients and records, at every step, what the
# encoder and the policy saw (`StepInputs`: observation, previous action probabilities,
# i_tau). The loss then recomputes s_t and the logits from those inputs as a
# differentiable function of the parameters, as PureJaxRL's `ppo_rnn.py` does in its
# `_loss_fn`. The environment's outputs carry no gradient, so this is the same function of
# the parameters as the acting pass, and its gradient equals differentiating through the
# acting scan (`gradient='through_rollout'`, the reference; tests/agent/test_train_replay.py checks
# both agree). It is fast because the encoder up to the LSTM's input gates has no
# recurrence: it runs once over all T x B steps of the window (a few large matmuls
# instead of T small ones), and only the LSTM's recurrent step is sequential. Nothing is
# reused from acting but the inputs, so it is right for any parameters fixed over the
# window; it is NOT right where they change inside one (MAML's adapted parameters): such
# methods declare `gradients = ('through_rollout',)` and `Config` refuses the replay.


def replayed(nets: Networks, params, traj: Trajectory, initial_carry: LSTMCarry, offset=None) -> Trajectory:
    """`traj` (recorded with `record_inputs=True`) with its states `[T, B, H]` and logits
    `[T, B, A]` recomputed as a differentiable function of `params`, through the two
    methods acting calls at T = 1: `ActorCritic.encode` over the window, then
    `ActorCritic.heads` on the recorded i_tau.

    initial_carry: the LSTM carry `(c, h)` `[B, H]` each before the window's first step
    (`ActorState.lstm` at the window's start). The carry is zeroed before every step that
    begins an episode (`traj.episode_step == 0`), as acting does.
    """
    if traj.inputs is None:
        raise ValueError("replay needs a trajectory recorded with record_inputs=True")
    seen = jax.lax.stop_gradient(traj.inputs)
    inputs = EncoderInputs(seen.obs, seen.prev_action_probs, seen.encoder_imagined)
    _, states = nets.model.apply(params, initial_carry, inputs, traj.episode_step == 0, method=ActorCritic.encode)
    if offset is not None:  # zeros whose gradient is the loss's at s_t (`Trainer.loss_and_grad_with_target`)
        states = states + offset
    logits = nets.model.apply(params, states, seen.imagined, method=ActorCritic.policy_logits)
    return traj._replace(states=states, logits=logits)


def window_critic(
    nets: Networks, params, traj: Trajectory, end: WindowEnd, memory: chex.Array | None
) -> tuple[CriticOutput, chex.Array]:
    """The critic over a window, the state after it (`end`) included: (CriticOutput with
    value `[T + 1, B]` (row T: V(s*_T), the bootstrap), alpha `[B, T + 1, M + T + 1]` or
    None; keys `[B, M + T + 1, H]`, what alpha weighs).

    Each step attends over the states of its own episode up to itself (Eq. 3-4): those of
    earlier windows (`memory` `[B, M, H]`, the ActorState's at the window's start, without
    gradient; None: no memory) and the window's."""
    if memory is None:
        memory = jnp.zeros((traj.states.shape[1], 0, traj.states.shape[2]), traj.states.dtype)
    states = jnp.concatenate([traj.states, end.state[None]], axis=0)  # [T + 1, B, H]
    steps = jnp.concatenate([traj.episode_step, end.episode_step[None]], axis=0)  # [T + 1, B]
    states, steps = jnp.swapaxes(states, 0, 1), jnp.swapaxes(steps, 0, 1)  # [B, T + 1, ...]
    keys = jnp.concatenate([jax.lax.stop_gradient(memory), states], axis=1)  # [B, M + T + 1, H]
    mask = window_attention_mask(steps, memory.shape[1])
    out = nets.model.apply(params, states, jnp.ones(steps.shape, bool), keys, mask, steps, method=ActorCritic.critic)
    return out._replace(value=jnp.swapaxes(out.value, 0, 1)), keys


class Trainer:
    """The pure functions of one training run of `config` (see module docstring)."""

    def __init__(self, config: Config, env=None, env_params=None):
        if env is None:
            env, env_params = make_env(config)
        env = imagination.label_env(config, env)  # the training labels' wrapper (none without a target)
        limit = int(jnp.max(env_params.max_steps))
        self.packed = config.rollout == "packed"
        if not self.packed and config.num_steps < limit:
            raise ValueError(
                f"num_steps ({config.num_steps}) must be at least the environment's training time limit "
                f"({limit}) with rollout='episodes' (one update runs whole episodes); use rollout='packed' "
                f"for shorter windows"
            )
        self.config = config
        self.env = env
        self.env_params = env_params
        self.networks = build(config)
        # The base's window, chosen once: SAVN's inner loop adapts the parameters inside
        # each episode (maml.act, whole episodes); every other base acts under one set.
        self.act_window = maml.act if config.pieces.base_piece.adapts_in_episode else rollout.act_window
        # The attention critic remembers a running episode's states across windows: at most
        # the time limit's worth. Whole-episode updates carry nothing across updates.
        self.memory_size = limit if self.packed and config.pieces.attention_critic else 0
        self.optimizer = optax.chain(optax.clip_by_global_norm(config.max_grad_norm), optax.adam(config.learning_rate))
        self.imagination_optimizer = self.networks.imagination.optimizer  # f_w's (the probes read it)

    def bind(self, env_params) -> BoundEnv:
        """The trainer's environment bound to `env_params` (those `run` was given), once
        per update: everything below acts in the `BoundEnv`."""
        return BoundEnv(self.env, env_params)

    # ------------------------------------------------------------------ state
    def init(self, key: chex.PRNGKey) -> RunnerState:
        cfg = self.config
        k_obs, k_params, k_actor, key = jax.random.split(key, 4)
        obs, _ = self.env.reset(k_obs, self.env_params)
        params, w_params = self.networks.init(k_params, obs)
        goal_size = obs["target"].shape[-1]
        lanes = lambda x: jnp.broadcast_to(x, (cfg.num_lanes,) + x.shape)  # noqa: E731
        buffers = jax.tree.map(lanes, imagination.buffer_init(cfg.buffer_size, cfg.hidden_size, goal_size))
        actor = rollout.start(self.networks, k_actor, self.bind(self.env_params), cfg.num_lanes, self.memory_size)
        # The target's head from a key of its own, folded from the model's: the keys above are the base's.
        head = imagination.target_init(cfg, jax.random.fold_in(k_params, 1), self.optimizer)
        return RunnerState(
            params, self.optimizer.init(params), w_params, buffers, actor, key, jnp.zeros((), jnp.int32), head
        )

    # ------------------------------------------------------------------ the loss
    def window_loss(self, params, traj: Trajectory, end: WindowEnd, memory: chex.Array):
        """The A3C loss (Eq. 8-9) of one window whose states and logits are differentiable
        in `params`, `end` what follows it. memory: the critic's memory at the window's
        start `[B, M, H]` (or None).
        Returns (loss, (alpha `[B, T + 1, K]` or None, key_states `[B, K, H]`, metrics))."""
        cfg = self.config
        critic, key_states = window_critic(self.networks, params, traj, end, memory)
        value, bootstrap = critic.value[:-1], critic.value[-1]  # [T, B], [B] V(s*_T)
        if not self.packed:
            bootstrap = jnp.zeros_like(bootstrap)  # whole episodes: nothing to bootstrap
        advantage, returns = advantages_and_returns(
            traj.rewards,
            value,
            traj.terminated,
            traj.truncated,
            traj.valid,
            bootstrap,
            cfg.gamma,
            cfg.gae_lambda,
        )
        loss, metrics = a3c_loss(
            traj.logits,
            traj.actions,
            value,
            advantage,
            returns,
            traj.valid,
            cfg.entropy_coef,
            cfg.value_coef,
        )
        return loss, (critic.alpha, key_states, metrics)

    def act(
        self, acting: AgentParams, env: BoundEnv, actor: ActorState, key
    ) -> tuple[ActorState, Trajectory, WindowEnd]:
        """One window of every lane (inputs recorded, for the replay and the buffers)."""
        options = ActOptions(whole_episodes=not self.packed, record_inputs=True)
        return self.act_window(self.networks, acting, env, actor, key, self.config.num_steps, options)

    def loss_and_grad(self, params, w_params, env: BoundEnv, actor: ActorState, key):
        """((loss, WindowResult), grads) of one window with respect to `params`, by the
        config's gradient path (see `Config.gradient`; both give the same gradient)."""
        if self.config.gradient == "replay":
            next_actor, traj, end = self.act(AgentParams(params, w_params), env, actor, key)

            def loss_fn(p):
                replay_traj = replayed(self.networks, p, traj, actor.agent.lstm)
                loss, aux = self.window_loss(p, replay_traj, end, actor.memory)
                return loss, WindowResult(next_actor, replay_traj, *aux)

        else:

            def loss_fn(p):
                next_actor, traj, end = self.act(AgentParams(p, w_params), env, actor, key)
                loss, aux = self.window_loss(p, traj, end, actor.memory)
                return loss, WindowResult(next_actor, traj, *aux)

        return jax.value_and_grad(loss_fn, has_aux=True)(params)

    # ------------------------------------------------------------------ one update
    def begin_window(self, actor: ActorState, key, env: BoundEnv) -> tuple[ActorState, chex.PRNGKey, chex.PRNGKey]:
        """(the lanes at the window's start, the next key, the window's acting key)."""
        key, k_act, k_start = jax.random.split(key, 3)
        if not self.packed:  # SAVN's layout: every lane starts a fresh episode
            tracker = actor.agent.imagination.tracker
            actor = rollout.start(self.networks, k_start, env, self.config.num_lanes, 0, tracker=tracker)
        return actor, key, k_act

    def update(self, state: RunnerState, env_params) -> tuple[RunnerState, dict]:
        cfg, env = self.config, self.bind(env_params)
        actor, key, k_act = self.begin_window(state.actor, state.key, env)
        rho = jax.vmap(imagination.success_rate)(actor.agent.imagination.tracker)  # [B] at the window's start
        head = state.targets
        if head is None:
            (loss, window), grads = self.loss_and_grad(state.params, state.imagination_params, env, actor, k_act)
        else:  # an auxiliary target: its head trains beside the agent, on its own optimiser state
            (loss, window), grads, head_grads = loss_and_grad_with_target(
                self, state.params, state.imagination_params, env, actor, k_act, head.params
            )
            head_updates, head_opt_state = self.optimizer.update(head_grads, head.opt_state, head.params)
            head = imagination.TargetState(optax.apply_updates(head.params, head_updates), head_opt_state)
        next_actor, traj, alpha, key_states, metrics = window
        updates, opt_state = self.optimizer.update(grads, state.opt_state, state.params)
        params = optax.apply_updates(state.params, updates)

        metrics = dict(metrics)
        ended, stats = ended_episodes(traj)
        num_ended = jnp.sum(ended.astype(jnp.float32))

        def per_episode(x):  # mean over the episodes that ended in this window
            return jnp.sum(jnp.where(ended, x, 0).astype(jnp.float32)) / jnp.maximum(num_ended, 1.0)

        useful = jnp.sum(traj.valid.astype(jnp.float32))
        stepped = float(traj.valid.size)
        metrics.update(
            {
                "charts/success_rate": per_episode(stats.success),
                "charts/spl": per_episode(stats.spl),
                "charts/episode_length": per_episode(stats.length),
                "charts/optimal_length": per_episode(stats.optimal_length),
                "charts/episodes": num_ended,
                "charts/useful_fraction": useful / stepped,
                "charts/padded_fraction": (stepped - useful) / stepped,
                "charts/noise_variance": jnp.mean(imagination.noise_variance(rho, cfg.sigma2_max)),
                "charts/moving_success_rate": jnp.mean(rho),
                "frames/useful": useful,
                "frames/stepped": jnp.asarray(stepped, jnp.float32),
                "losses/grad_norm": optax.tree.norm(grads),
            }
        )
        # f_w's part (Algorithm 1): the window's sub-goals into the buffers, full buffers into f_w.
        w_params, buffers, imag_metrics = imagination.learn(
            self.networks.imagination, state.imagination_params, state.buffers, traj, alpha, key_states, stats.success
        )
        metrics.update(imag_metrics)
        new_state = RunnerState(params, opt_state, w_params, buffers, next_actor, key, state.update + 1, head)
        return new_state, metrics

    def run(
        self, state: RunnerState, env_params, num_updates: int, on_update: Callable | None = None
    ) -> tuple[RunnerState, dict]:
        """`num_updates` updates in a `lax.scan`; metrics stacked `[num_updates]`.

        `on_update`, if given, is a host function called after every `PROGRESS_EVERY`-th
        update with the state's update count (`jax.debug.callback`; under vmap the condition
        is batched, so it is called after every update, once per seed): for a
        progress display inside a long jitted chunk. It reads a counter only, so the
        numbers are those of a run without it (tests/agent/test_train.py)."""

        def body(s, _):
            s, metrics = self.update(s, env_params)
            if on_update is not None:  # every PROGRESS_EVERY-th update (a callback per update slows training)
                jax.lax.cond(
                    s.update % PROGRESS_EVERY == 0, lambda: jax.debug.callback(on_update, s.update), lambda: None
                )
            return s, metrics

        return jax.lax.scan(body, state, None, length=num_updates)

    @functools.cached_property
    def run_seeds(self):
        """`run` of several seeds at once, jitted: (states with a leading seed axis,
        env_params, num_updates (static)) -> (states, metrics `[seeds, num_updates]`).
        Built once per Trainer, so that every chunk (and every sweep of this Trainer)
        reuses its compiled programs; the seed axis may be sharded over devices."""
        return seeds_runner(self, None)

    def train(self, key: chex.PRNGKey) -> tuple[RunnerState, dict]:
        """The whole run in one jittable function: init, then `config.num_updates` updates."""
        return self.run(self.init(key), self.env_params, self.config.num_updates)


def loss_and_grad_with_target(trainer: Trainer, params, w_params, env: BoundEnv, actor: ActorState, key, head_params):
    """`trainer`'s ((loss, WindowResult), grads of `params`, grads of the target's head) of one window:
    the A3C loss plus `aux_weight` times the target's (`imagination.target_window_loss`), by the
    replay (`Config` refuses a target elsewhere). The head learns its own loss at full
    weight; lambda scales only the gradient that reaches the encoder through s_t:

        L = L_A3C(theta) + lambda * L_aux(s_t(theta), sg(head)) + L_aux(sg(s_t), head)

    so lambda = 0 leaves the agent's gradient the base's. `losses/aux_grad_ratio`: the
    norm of the target's gradient at s_t (the encoder's output, through which alone
    either loss reaches the encoder) over the actor-critic's, from zero offsets added
    to s_t (`replayed`'s `offset`), whose gradients are those two."""
    cfg = trainer.config
    next_actor, traj, end = trainer.act(AgentParams(params, w_params), env, actor, key)
    zeros = jnp.zeros_like(traj.states)
    obs = jax.lax.stop_gradient(traj.inputs.obs)

    def goal_latent(flat_obs):  # the goal view's latent under this update's parameters
        return trainer.networks.goal_latent(jax.lax.stop_gradient(params), None, flat_obs)

    def loss_fn(p, head, offset_ac, offset_aux):
        replay_traj = replayed(trainer.networks, p, traj, actor.agent.lstm, offset_ac)
        loss, aux = trainer.window_loss(p, replay_traj, end, actor.memory)
        states = replay_traj.states - offset_ac + offset_aux  # s_t, seen by the target through its own offset
        labels = imagination.target_labels(cfg, obs, jax.lax.stop_gradient(states), traj, goal_latent)
        to_encoder, _ = imagination.target_window_loss(cfg, jax.lax.stop_gradient(head), states, labels)
        aux_loss, aux_metrics = imagination.target_window_loss(cfg, head, jax.lax.stop_gradient(states), labels)
        alpha, key_states, metrics = aux
        valid = jnp.maximum(jnp.sum(traj.valid.astype(jnp.float32)), 1.0)
        metrics = {
            **metrics,
            **aux_metrics,
            "charts/aux_labelled_fraction": aux_metrics["charts/aux_labelled"] / valid,
        }
        total = loss + cfg.aux_weight * to_encoder + aux_loss
        return total, WindowResult(next_actor, replay_traj, alpha, key_states, metrics)

    (total, window), (grads, head_grads, g_ac, g_aux) = jax.value_and_grad(loss_fn, argnums=(0, 1, 2, 3), has_aux=True)(
        params, head_params, zeros, zeros
    )
    ratio = optax.tree.norm(g_aux) / jnp.maximum(optax.tree.norm(g_ac), 1e-12)
    window = window._replace(metrics={**window.metrics, "losses/aux_grad_ratio": ratio})
    return (total, window), grads, head_grads


def seeds_runner(trainer: Trainer, on_update: Callable | None):
    """`trainer.run_seeds` with `on_update` (see `Trainer.run`): jitted, vmapped over the seeds."""
    return jax.jit(
        jax.vmap(functools.partial(trainer.run, on_update=on_update), in_axes=(0, None, None)), static_argnums=2
    )


def collect_subgoal_items(trainer: Trainer, state: RunnerState, env_params, num_windows: int):
    """What `num_windows` windows that `trainer` plays with the agent of `state` (not updated) offer
    the buffers: ((s_0, g_tau, ŝ_tau, add), (t*, step)), each `[num_windows, T, B, ...]`:
    the items (`subgoal_items`; the data of the paper's C-VAE comparison), the position
    of each step's sub-goal in its episode (`subgoal_steps`) and the step's own
    position (at an `add` step, the Done step's: the episode's length - 1)."""

    env = trainer.bind(env_params)

    def window(carry, _):
        actor, key, k_act = trainer.begin_window(*carry, env)
        next_actor, traj, end = trainer.act(AgentParams(state.params, state.imagination_params), env, actor, k_act)
        _, (alpha, key_states, _) = trainer.window_loss(state.params, traj, end, actor.memory)  # the critic's alpha
        _, stats = ended_episodes(traj)
        items = imagination.subgoal_items(
            trainer.networks.imagination_variant.subgoal_mode, traj, alpha, key_states, stats.success
        )
        steps = imagination.subgoal_steps(traj.episode_step, end.episode_step, alpha)
        return (next_actor, key), (items, (steps, traj.episode_step))

    _, items = jax.lax.scan(window, (state.actor, state.key), None, length=num_windows)
    return items


class GridTrainer(Trainer):
    """A Trainer whose learning rate is an input: `init(key, learning_rate)`, then `run` as
    `Trainer`'s. The rate sits in the optimiser state (`optax.inject_hyperparams`, Adam's
    other settings kept static), so runs at several rates vmap with the seeds in one XLA
    program: one compilation for a grid, side by side on an accelerator.

        grid = GridTrainer(config)
        keys, rates = grid_inputs(seeds=[0, 1, 2], learning_rates=[3e-4, 1e-3])
        states, metrics = jax.jit(jax.vmap(grid.train))(keys, rates)    # [6, ...], rate-major

    What it equals (tests/agent/test_train.py, on one machine, XLA's default compile options):
    unvmapped, seed s at rate v trains as `Trainer(dataclasses.replace(config,
    learning_rate=v))` from `PRNGKey(s)` does, bit for bit (a3c, a3c+foresit, a3c+maml: the
    rate as an array multiplies as the constant does); vmapped over the seeds of one rate,
    it is the program `experiments.sweep` runs at that rate (`Trainer.run_seeds`), bit for
    bit. A grid of several rates in one program is a batch of V x S lanes instead of S,
    another XLA program: the per-rate sweeps up to float rounding, as a sweep's seed is
    `train --seed` up to float rounding. `experiments.tune` trains its arms one after
    another instead, each its own sweep: on a CPU of few cores the seeds' lanes already
    fill the cores (`benchmarks.bench_grid`; docs/reproducibility.md)."""

    # Adam's settings other than the rate stay Python constants: traced, they move the
    # parameters off `Trainer`'s by float rounding; with the rate alone traced, the
    # parameters are `Trainer`'s bit for bit (docs/reproducibility.md).
    STATIC_ADAM_ARGS = ("b1", "b2", "eps", "eps_root", "mu_dtype", "nesterov")

    def __init__(self, config: Config, env=None, env_params=None):
        super().__init__(config, env, env_params)
        adam = optax.inject_hyperparams(optax.adam, static_args=self.STATIC_ADAM_ARGS)
        self.optimizer = optax.chain(
            optax.clip_by_global_norm(config.max_grad_norm), adam(learning_rate=config.learning_rate)
        )

    def init(self, key: chex.PRNGKey, learning_rate=None) -> RunnerState:
        """`Trainer.init` with Adam's rate set to `learning_rate` (a scalar, traced or not;
        None: the config's)."""
        state = super().init(key)
        if learning_rate is None:
            return state
        clip, adam = state.opt_state
        rate = jnp.asarray(learning_rate, adam.hyperparams["learning_rate"].dtype)
        return state._replace(opt_state=(clip, adam._replace(hyperparams={**adam.hyperparams, "learning_rate": rate})))

    @staticmethod
    def learning_rate(state: RunnerState) -> chex.Array:
        """The rate a state trains at (`[]`, or `[N]` for a vmapped grid's states)."""
        return state.opt_state[1].hyperparams["learning_rate"]

    def train(self, key: chex.PRNGKey, learning_rate=None) -> tuple[RunnerState, dict]:
        """The whole run at `learning_rate` in one jittable function (vmap it over a grid)."""
        return self.run(self.init(key, learning_rate), self.env_params, self.config.num_updates)


def grid_inputs(seeds, learning_rates) -> tuple[chex.Array, chex.Array]:
    """(keys `[V * S, 2]`, rates `[V * S]`) for `vmap(GridTrainer.train)`: every seed at
    every rate, rate-major (entry v * S + i is seed `seeds[i]` at `learning_rates[v]`,
    its key `PRNGKey(seeds[i])`, as `train --seed` makes it)."""
    seeds, rates = list(seeds), [float(r) for r in learning_rates]
    if not seeds or not rates:
        raise ValueError(f"grid_inputs: give at least one seed and one learning rate, got {seeds} and {rates}")
    if any(not r > 0 for r in rates):
        raise ValueError(f"grid_inputs: learning rates must be positive, got {rates}")
    keys = jnp.stack([jax.random.PRNGKey(s) for s in seeds])
    return jnp.tile(keys, (len(rates), 1)), jnp.repeat(jnp.asarray(rates, jnp.float32), len(seeds))


def make_trainer(config: Config, env=None, env_params=None) -> Trainer:
    return Trainer(config, env, env_params)


def make_train(config: Config, env=None, env_params=None) -> Callable[[chex.PRNGKey], tuple[RunnerState, dict]]:
    """PureJaxRL's entry point: `train(key) -> (final RunnerState, metrics [num_updates])`."""
    return make_trainer(config, env, env_params).train
