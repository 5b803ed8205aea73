"""The acting agent: one rollout function shared by training and evaluation.

An `Agent` ties the networks of a `Config` together (encoder + policy + critic under one
parameter tree, theta and omega; f_w under its own tree, w) and runs batched episodes
against any environment with the GridNav API (``reset``/``step`` on a batch via vmap).
Evaluation calls `rollout` alone. Training calls it without gradients, recording what
the encoder saw at each step, then `replay` recomputes s_t and the logits from those
inputs, differentiably (the environment's outputs carry no gradient, so this is the same
function of the parameters as the acting pass, and the gradient is that of
differentiating through the rollout). The replay applies everything before the LSTM's
recurrence to all the episode's real steps at once (a few large matmuls instead of one
small one per step) and skips the padding; only the recurrent step is sequential.
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple, Optional

import chex
import jax
import jax.numpy as jnp

from foresit_jax import distributions, imagination
from foresit_jax.config import Config
from foresit_jax.networks import (
    LSTM_GATES,
    ActorCritic,
    ImaginationNet,
    LSTMKernels,
    initial_carry,
    lstm_input_gates,
    lstm_kernels,
    lstm_step,
    lstm_input_kernel_t,
    with_transposed_recurrent_kernel,
)


class StepInputs(NamedTuple):
    """What the encoder and the policy saw at each step of a rollout (for `Agent.replay`)."""

    obs: Any  # observation dict, leaves [T, B, ...]
    prev_action_probs: chex.Array  # [T, B, A]
    imagined: Optional[chex.Array]  # [T, B, H] i_tau given to the policy; None without imagination
    input_gates: chex.Array  # [T, B, 4H] the LSTM input's part of the gates, as computed while acting


class Trajectory(NamedTuple):
    """One padded episode per lane, time-major."""

    states: chex.Array  # [T, B, H] s_t (LSTM hidden state)
    logits: chex.Array  # [T, B, A]
    actions: chex.Array  # [T, B] int32
    rewards: chex.Array  # [T, B]
    terminated: chex.Array  # [T, B] bool, Done taken
    truncated: chex.Array  # [T, B] bool, time limit reached
    valid: chex.Array  # [T, B] bool, step belongs to the lane's first episode
    success: chex.Array  # [T, B] bool, successful Done at this step
    target: chex.Array  # [B, D] g_tau of the episode
    optimal_length: chex.Array  # [B] int32 L^g of the episode
    room_type: chex.Array  # [B] int32
    inputs: Optional[StepInputs] = None  # recorded by rollout(record_inputs=True)


class EpisodeStats(NamedTuple):
    success: chex.Array  # [B] bool
    length: chex.Array  # [B] int32 actions taken, Done included
    optimal_length: chex.Array  # [B] int32
    spl: chex.Array  # [B] float32 success * L^g / max(L, L^g)
    ended: chex.Array  # [B] bool, the episode ended inside the rollout
    room_type: chex.Array  # [B] int32


def episode_stats(traj: Trajectory) -> EpisodeStats:
    valid = traj.valid
    length = jnp.sum(valid.astype(jnp.int32), axis=0)
    success = jnp.any(traj.success & valid, axis=0)
    ended = jnp.any((traj.terminated | traj.truncated) & valid, axis=0)
    opt = traj.optimal_length
    spl = success * opt / jnp.maximum(length, opt).astype(jnp.float32)
    return EpisodeStats(success, length, opt, spl.astype(jnp.float32), ended, traj.room_type)


def replay_chunk_rows(num_steps: int, num_lanes: int) -> int:
    """Steps per chunk of `Agent.replay`'s gradient: a quarter of the rollout (so with a
    fraction p of padding, about ceil(4 (1 - p)) chunks are differentiated), and at least
    128 rows (or the whole rollout) for an efficient matmul."""
    size = num_steps * num_lanes
    return min(size, max(128, -(-size // 4)))


class Agent:
    """Networks and acting for one method (a `Config`)."""

    def __init__(self, config: Config):
        self.config = config
        flags = config.flags
        self.flags = flags
        self.model = ActorCritic(
            num_actions=config.num_actions,
            hidden_size=config.hidden_size,
            use_imagination=flags.uses_imagination,
            attention_critic=flags.attention_critic,
            attention_size=config.attention_size,
            value_hidden=config.value_hidden,
        )
        self.imagination_net = ImaginationNet(config.imagination_layer_sizes)

    # ------------------------------------------------------------------ init
    def init(self, key: chex.PRNGKey, obs: dict) -> tuple[Any, Any]:
        """(theta/omega params, f_w params) from one unbatched observation."""
        k_model, k_imag = jax.random.split(key)
        hidden = self.config.hidden_size
        carry = initial_carry((), hidden)
        probs = jnp.zeros((self.config.num_actions,), jnp.float32)
        imagined = jnp.zeros((hidden,), jnp.float32) if self.flags.uses_imagination else None
        params = self.model.init(k_model, carry, obs, probs, imagined)
        w_params = self.imagination_net.init(k_imag, jnp.zeros((hidden,)), obs["target"])
        return params, w_params

    def imagine(self, w_params, s_0: chex.Array, goal: chex.Array) -> chex.Array:
        """f_w([s_0 : g_tau]) `[..., H]`."""
        return self.imagination_net.apply(w_params, s_0, goal)

    def _imagined_subgoal(self, w_params, s_t, goal, key, sigma2):
        """i_tau for the policy (stop-gradient: the policy loss never trains f_w or,
        through it, s_0).  ForeSIT: f_w + N(0, sigma2); rnd: tanh(N(0, 0.5))."""
        if self.flags.imagination == "random":
            return imagination.random_imagination(key, s_t.shape, self.config.rnd_variance)
        imagined = self.imagine(w_params, jax.lax.stop_gradient(s_t), goal)
        return jax.lax.stop_gradient(imagination.add_imagination_noise(key, imagined, sigma2))

    # ------------------------------------------------------------------ acting
    def rollout(
        self, params, w_params, env, env_params, key, sigma2, num_steps: int, greedy: bool = False,
        record_inputs: bool = False,
    ):  # fmt: skip
        """Reset every lane and run its episode for `num_steps` steps (padded, masked).

        sigma2: `[B]` imagination-noise variance per lane; its length sets the batch.
        Returns a `Trajectory`.  Steps after a lane's episode ended are padding
        (valid=False): the environment auto-resets, and what follows is ignored.
        record_inputs: also return each step's encoder and policy inputs
        (`Trajectory.inputs`, for `replay`).
        """
        num_lanes = sigma2.shape[0]
        hidden = self.config.hidden_size
        k_reset, k_steps = jax.random.split(key)
        obs, env_state = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(k_reset, num_lanes), env_params)
        goal = obs["target"]  # [B, D]
        optimal_length = env_state.optimal_length
        room_type = env_state.room_type
        model = self.model
        flags, interval = self.flags, self.config.int_interval
        kernels = self._lstm_kernels(params)  # concatenated once, outside the loop

        def step(carry, inputs):
            t, key = inputs
            lstm, prev_probs, imagined, env_state, obs, alive = carry
            k_imag, k_act, k_env = jax.random.split(key, 3)
            # Together, model.apply(params, lstm, obs, prev_probs, method=ActorCritic.encode).
            input_gates = self.input_gates(params, obs, prev_probs, kernels)  # [B, 4H]
            lstm, s_t = lstm_step(kernels, lstm, input_gates)
            if flags.uses_imagination:
                renew = t == 0
                if flags.reimagine_every_k:
                    renew = t % interval == 0
                imagined = jax.lax.cond(
                    renew,
                    lambda: self._imagined_subgoal(w_params, s_t, goal, k_imag, sigma2),
                    lambda: imagined,
                )
            policy_input = imagined if flags.uses_imagination else None
            logits = model.apply(params, s_t, policy_input, method=ActorCritic.policy_logits)
            action = distributions.greedy(logits) if greedy else distributions.sample(k_act, logits)
            seen = StepInputs(obs, prev_probs, policy_input, input_gates) if record_inputs else None
            obs, env_state, reward, term, trunc, info = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
                jax.random.split(k_env, num_lanes), env_state, action, env_params
            )
            out = (s_t, logits, action, reward, term, trunc, alive, info["success"] & alive, seen)
            probs = jax.lax.stop_gradient(distributions.probs(logits))
            return (lstm, probs, imagined, env_state, obs, alive & ~(term | trunc)), out

        init = (
            initial_carry((num_lanes,), hidden),
            jnp.zeros((num_lanes, self.config.num_actions), jnp.float32),
            jnp.zeros((num_lanes, hidden), jnp.float32),
            env_state,
            obs,
            jnp.ones((num_lanes,), bool),
        )
        steps = (jnp.arange(num_steps), jax.random.split(k_steps, num_steps))
        _, out = jax.lax.scan(step, init, steps)
        states, logits, actions, rewards, term, trunc, valid, success, seen = out
        return Trajectory(states, logits, actions, rewards, term, trunc, valid, success, goal,
                          optimal_length, room_type, seen)  # fmt: skip

    def _lstm_kernels(self, params) -> LSTMKernels:
        return lstm_kernels(params["params"]["encoder"]["lstm"])

    def input_gates(self, params, obs, prev_action_probs, kernels: Optional[LSTMKernels] = None):
        """The encoder up to the LSTM's input gates `[..., 4H]`: everything of a step
        that does not depend on the LSTM carry."""
        kernels = self._lstm_kernels(params) if kernels is None else kernels
        features = self.model.apply(params, obs, prev_action_probs, method=ActorCritic.encoder_features)
        return lstm_input_gates(kernels, features)

    def replay(self, params, traj: Trajectory):
        """Recompute (states `[T, B, H]`, logits `[T, B, A]`) of a rollout recorded with
        `record_inputs=True`, as a differentiable function of `params`.

        The values are the acting pass's, bit for bit: the LSTM's input gates are the
        recorded ones, then the recurrent step and the policy run step by step on them,
        as when acting. The gradient is that of the same function, computed for speed:
        everything before the recurrence (encoder and input projection) is
        differentiated for all the real steps of all lanes at once, in chunks of
        `replay_chunk_rows` steps, skipping the padding (which the loss masks: its
        gradient is zero); see `_recorded_input_gates`.
        """
        inputs = jax.lax.stop_gradient(traj.inputs)
        num_steps, num_lanes = traj.valid.shape
        size = num_steps * num_lanes
        model = self.model
        kernels = with_transposed_recurrent_kernel(self._lstm_kernels(params))

        def flat(x):  # [T, B, ...] -> [T * B, ...]
            return x.reshape((size,) + x.shape[2:])

        obs, probs, recorded = jax.tree.map(flat, (inputs.obs, inputs.prev_action_probs, inputs.input_gates))
        rows = replay_chunk_rows(num_steps, num_lanes)
        gates = _recorded_input_gates(self, rows, params, obs, probs, recorded, flat(traj.valid))
        gates = gates.reshape(num_steps, num_lanes, -1)  # [T, B, 4H]

        def step(carry, xs):
            input_gates, imagined = xs
            carry, s_t = lstm_step(kernels, carry, input_gates)
            logits = model.apply(params, s_t, imagined, method=ActorCritic.policy_logits)
            return carry, (s_t, logits)

        carry = initial_carry((num_lanes,), self.config.hidden_size)
        _, (states, logits) = jax.lax.scan(step, carry, (gates, inputs.imagined))
        return states, logits

    def critic(self, params, traj: Trajectory):
        """Critic over each lane's episode: CriticOutput with value `[T, B]`, alpha
        `[B, T, T]` (None for the plain critic)."""
        out = self.model.apply(
            params, jnp.swapaxes(traj.states, 0, 1), jnp.swapaxes(traj.valid, 0, 1),
            method=ActorCritic.critic,
        )  # fmt: skip
        return out._replace(value=jnp.swapaxes(out.value, 0, 1))


@functools.partial(jax.custom_vjp, nondiff_argnums=(0, 1))
def _recorded_input_gates(agent: Agent, rows: int, params, obs, probs, recorded, valid):
    """`agent.input_gates(params, obs, probs)` `[N, 4H]`, whose value was computed while
    acting and is `recorded` `[N, 4H]`: returns it. Its gradient differentiates the
    `valid` `[N]` rows only (the loss gives the padding a zero cotangent), `rows` at a
    time: the valid rows are gathered first, and a `while_loop` visits only the chunks
    that hold some."""
    return recorded


def _recorded_input_gates_fwd(agent, rows, params, obs, probs, recorded, valid):
    return recorded, (params, obs, probs, valid)


def _recorded_input_gates_bwd(agent, rows, residuals, cotangent):
    params, obs, probs, valid = residuals
    size = valid.shape[0]
    input_kernel_t = lstm_input_kernel_t(params["params"]["encoder"]["lstm"])  # [4H, F], once for all chunks
    order = jnp.argsort(jnp.logical_not(valid), stable=True)  # valid rows first
    num_chunks = -(-size // rows)
    order = jnp.pad(order, (0, num_chunks * rows - size))
    needed = -(-jnp.sum(valid.astype(jnp.int32)) // rows)

    def chunk(k):
        index = jax.lax.dynamic_slice_in_dim(order, k * rows, rows)
        # Rows past the valid ones have a zero cotangent, except the repeats of row 0
        # that pad a last partial chunk: masked, so that no row counts twice.
        in_range = (k * rows + jnp.arange(rows)) < size
        g = jnp.where(in_range[:, None], cotangent[index], 0.0)  # [rows, 4H]
        return input_gates_chunk_vjp(agent, params, obs, probs, input_kernel_t, index, g)

    # Chunk 0 outside the loop (right whatever `needed` is: a chunk of padding adds
    # zeros), so the loop needs no zero-filled accumulator.
    d_feature_params, d_input_kernel = jax.lax.fori_loop(
        1, needed, lambda k, grads: jax.tree.map(jnp.add, grads, chunk(k)), chunk(0)
    )

    grads = jax.tree.map(jnp.zeros_like, params)
    d_encoder = {**grads["params"]["encoder"], **d_feature_params}
    d_lstm = dict(d_encoder["lstm"])
    for gate, d_kernel in zip(LSTM_GATES, jnp.split(d_input_kernel, len(LSTM_GATES), axis=-1)):
        d_lstm["i" + gate] = {**d_lstm["i" + gate], "kernel": d_kernel}
    d_encoder["lstm"] = d_lstm
    return {**grads, "params": {**grads["params"], "encoder": d_encoder}}, None, None, None, None


def _feature_params(params):
    """The encoder's parameters before the LSTM (convolutions, embeddings, object graph)."""
    return {name: p for name, p in params["params"]["encoder"].items() if name != "lstm"}


def input_gates_chunk_vjp(agent: Agent, params, obs, probs, input_kernel_t, index, g):
    """The gradient of `vdot(g, agent.input_gates(params, obs[index], probs[index]))`:
    (for the encoder's feature parameters, for the LSTM's concatenated input kernel
    `[F, 4H]`), with `input_kernel_t` its `materialized_transpose` (so that both
    products are plain matmuls). One chunk of `Agent.replay`'s gradient."""
    encoder = params["params"]["encoder"]

    def features(feature_params):  # [rows, F]
        chunk_params = {**params, "params": {**params["params"], "encoder": {**encoder, **feature_params}}}
        chunk_obs = jax.tree.map(lambda x: x[index], obs)
        return agent.model.apply(chunk_params, chunk_obs, probs[index], method=ActorCritic.encoder_features)

    x, features_vjp = jax.vjp(features, _feature_params(params))
    (d_feature_params,) = features_vjp(jnp.dot(g, input_kernel_t))  # d x = g W^T
    return d_feature_params, jnp.dot(x.T, g)  # d W = x^T g


_recorded_input_gates.defvjp(_recorded_input_gates_fwd, _recorded_input_gates_bwd)
