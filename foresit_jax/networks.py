"""Flax (linen) modules of the ForeSIT agent (Sections 3-4, implementation in 5.2).

* `Encoder`: SAVN's observation encoder, one LSTM step; s_t is the LSTM hidden state.
* `PolicyHead`: one linear layer over [s_t : i_tau] (over s_t alone without ForeSIT).
* `Critic`: value head, plain (MLP on s_t, A3C baseline) or with the attention of
  Eq. 3-4 over the current episode's states (MLP on s*_t, ForeSIT).
* `ImaginationNet`: f_w, 6 tanh layers with a bottleneck, [s_0 : g_tau] -> imagined s.
* `ActorCritic`: Encoder + PolicyHead + Critic under one parameter tree (theta, omega),
  reached through two time-major methods that acting and the loss both call, as in
  PureJaxRL's `ppo_rnn.py`: `encode` (the encoder over T steps: the input gates of all
  steps in one matmul, then the LSTM's recurrence) and `heads` (the policy's logits on
  [s_t : i_tau]); acting calls them at T = 1 and imagines i_tau between the two calls, the
  loss at T = the window on the recorded i_tau. Plus `critic` (values over a window).
* `build(config) -> Networks`: the one place where a method's pieces (flags,
  `foresit_jax.methods`) become modules: ORG's object graph, SAVN's learned loss, the
  attention critic, where i_tau enters. `Networks` is a record (the modules and the
  Config), what `foresit_jax.rollout` acts with.
* Pure helpers: `causal_episode_mask`, `window_attention_mask` (which states each step
  attends to), `masked_softmax`, `subgoals_of_rows` (the sub-goal each attention row
  selects). The LSTM cell's split form (used by acting and the replay gradient) is in
  `foresit_jax.lstm`.

Every module works unbatched or with any leading batch dims (Dense acts on the last
axis); the critic's time axis is the second to last of `states`.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, Mapping, NamedTuple, Optional, Sequence

import chex
import flax.linen as nn
import jax
import jax.numpy as jnp

from foresit_jax.config import Config
from foresit_jax.layers import Dense, GridDense, orthogonal
from foresit_jax.lstm import (  # noqa: F401 (initial_carry, reset_carry: re-exported)
    EncoderLSTM,
    LowRankUpdate,
    LSTMCarry,
    LSTMKernels,
    initial_carry,
    reset_carry,
)
from foresit_jax.learned_loss import LearnedLoss
from foresit_jax.methods import Method, ImaginationVariant
from foresit_jax.org import ObjectGraph


class Encoder(nn.Module):
    """SAVN encoder: observation, target and previous action probabilities -> s_t.

    view `[..., 3, W, Cv]` -> 1x1 conv to `conv_features` (ReLU);
    target `[..., D]` -> linear `target_features` (ReLU), tiled over the 3 x W grid;
    previous action probabilities `[..., A]` -> linear `action_features` (ReLU), tiled;
    concat -> 1x1 conv to `conv_features` (ReLU) -> flatten -> LSTM cell `hidden_size`.
    A 1x1 convolution is a Dense layer over the channel axis, which is how it is written.

    `imagination_features > 0` (`Config.imagination_input='encoder'`): i_tau `[..., H]` ->
    linear `imagination_features` (ReLU), tiled beside the target's and the action's
    embeddings; the caller passes zeros where no i_tau exists yet (an episode's first step).

    `object_graph` is the hook for the ORG baseline (setup 'org'): a module called as
    `object_graph(obs["detections"] [..., n_cat, 7], obs["target"] [..., D])` returning
    features `[..., F]` that are concatenated to the flattened grid before the LSTM.
    Unset (None), `obs["detections"]` is ignored.
    """

    hidden_size: int = 512
    conv_features: int = 64
    target_features: int = 64
    action_features: int = 10
    imagination_features: int = 0
    object_graph: Optional[nn.Module] = None

    def setup(self):
        self.view_conv = Dense(self.conv_features)
        self.target_embed = Dense(self.target_features)
        self.action_embed = Dense(self.action_features)
        if self.imagination_features:
            self.imagination_embed = Dense(self.imagination_features)
        self.pointwise_conv = GridDense(self.conv_features)
        self.lstm = EncoderLSTM(self.hidden_size)

    def features(
        self, obs: Mapping[str, chex.Array], prev_action_probs: chex.Array, imagined: Optional[chex.Array] = None
    ) -> chex.Array:
        """The LSTM's input `[..., 3 * W * conv_features (+ F)]`: everything before the cell.

        It depends on no carry, so a whole window's features can be computed at once
        (`foresit_jax.train.replayed`). `imagined [..., H]`: i_tau, only with `imagination_features`."""
        view = obs["view"]  # [..., 3, W, Cv]
        target = obs["target"]  # [..., D]
        batch_shape = target.shape[:-1]
        chex.assert_rank(view, len(batch_shape) + 3)
        chex.assert_equal_shape_prefix([view, target, prev_action_probs], len(batch_shape))

        image = nn.relu(self.view_conv(view))  # [..., 3, W, 64]
        goal = nn.relu(self.target_embed(target))  # [..., 64]
        action = nn.relu(self.action_embed(prev_action_probs))  # [..., 10]
        vectors = [goal, action]
        if self.imagination_features:
            if imagined is None:
                raise ValueError("Encoder(imagination_features > 0) needs i_tau (zeros where none exists yet).")
            chex.assert_equal_shape_prefix([imagined, target], len(batch_shape))
            vectors.append(nn.relu(self.imagination_embed(imagined)))  # [..., imagination_features]
        # The 1x1 conv of [image : tile(goal) : tile(action) (: tile(i_tau))] ([..., 3, W, 138
        # (+ 64)]), without building the tiled input (layers.GridDense: the same function, faster).
        x = nn.relu(self.pointwise_conv(image, *vectors))  # [..., 3, W, 64]
        x = x.reshape(*batch_shape, -1)  # [..., 3 * W * 64]

        if self.object_graph is not None:
            if "detections" not in obs:
                raise ValueError("Encoder.object_graph is set but obs has no 'detections'.")
            graph_features = self.object_graph(obs["detections"], target)  # [..., F]
            x = jnp.concatenate([x, graph_features], axis=-1)
        return x

    def __call__(
        self,
        carry: LSTMCarry,
        obs: Mapping[str, chex.Array],
        prev_action_probs: chex.Array,
        imagined: Optional[chex.Array] = None,
    ) -> tuple[LSTMCarry, chex.Array]:
        carry, s_t = self.lstm(carry, self.features(obs, prev_action_probs, imagined))
        return carry, s_t  # s_t: [..., hidden_size]


class PolicyHead(nn.Module):
    """Action logits over [s_t : i_tau] (or s_t alone): one linear layer, or with
    `hidden > 0` a two-layer MLP (Dense `hidden`, ReLU, then the linear layer).

    The output layer is initialised with a small orthogonal scale (0.01), as SAVN
    initialises its actor (norm_col_init 0.01), so the initial policy is near uniform.
    """

    num_actions: int = 6
    use_imagination: bool = True
    hidden: int = 0

    @nn.compact
    def __call__(self, s_t: chex.Array, imagined: Optional[chex.Array] = None) -> chex.Array:
        if self.use_imagination:
            if imagined is None:
                raise ValueError("PolicyHead(use_imagination=True) needs the imagined sub-goal.")
            chex.assert_equal_shape([s_t, imagined])
            x = jnp.concatenate([s_t, imagined], axis=-1)  # [..., 2H]
        else:
            x = s_t  # [..., H]
        if self.hidden:
            x = nn.relu(Dense(self.hidden, name="hidden")(x))  # [..., hidden]
        return Dense(self.num_actions, kernel_init=orthogonal(0.01), name="actor")(x)  # [..., A]


class ValueHead(nn.Module):
    """Two-layer MLP `[..., H] -> [...]` (Dense hidden, ReLU, Dense 1), the paper's value
    function; with `hidden` 0, one Dense layer (SAVN's linear critic)."""

    hidden: int = 256

    @nn.compact
    def __call__(self, x: chex.Array) -> chex.Array:
        if self.hidden:
            x = nn.relu(Dense(self.hidden, name="hidden")(x))
        return Dense(1, name="out")(x)[..., 0]


def causal_episode_mask(valid: chex.Array) -> chex.Array:
    """`[..., T] -> [..., T, T]` bool: entry (t, j) true iff j <= t and step j is valid."""
    num_steps = valid.shape[-1]
    causal = jnp.tril(jnp.ones((num_steps, num_steps), bool))  # [T, T]
    return causal & valid.astype(bool)[..., None, :]


def masked_softmax(scores: chex.Array, mask: chex.Array) -> chex.Array:
    """Softmax over the last axis restricted to `mask`; rows with no entry give zeros."""
    chex.assert_equal_shape([scores, mask])
    masked = jnp.where(mask, scores, jnp.finfo(scores.dtype).min)
    shifted = masked - jax.lax.stop_gradient(jnp.max(masked, axis=-1, keepdims=True))
    weights = jnp.exp(shifted) * mask
    return weights / jnp.maximum(jnp.sum(weights, axis=-1, keepdims=True), 1e-30)


def window_attention_mask(episode_step: chex.Array, memory_size: int) -> chex.Array:
    """Which keys each step of a packed window may attend to (Eq. 3-4: the states s_0..s_t
    of its own episode), `[..., T] -> [..., T, memory_size + T]` bool.

    `episode_step [..., T]` is each step's index in its episode (0 at an episode's first
    state). The keys are `[memory ; window]`: `memory [..., memory_size, H]` holds the
    states of the episode running when the window began (positions 0..episode_step[0]-1,
    from earlier windows), then the window's own states. Step t sees memory entry j iff
    no episode started in the window up to t and j < episode_step[0]; it sees window step
    j iff j <= t and j belongs to the same episode. No information crosses episodes.
    """
    first = episode_step == 0  # [..., T]
    episode_id = jnp.cumsum(first.astype(jnp.int32), axis=-1)  # [..., T] 0 = the carried episode
    carried = episode_id == 0  # [..., T]
    memory_count = episode_step[..., :1]  # [..., 1] states already in memory
    num_steps = episode_step.shape[-1]
    memory = carried[..., :, None] & (jnp.arange(memory_size) < memory_count[..., None])  # [..., T, M]
    causal = jnp.tril(jnp.ones((num_steps, num_steps), bool))  # [T, T]
    same_episode = episode_id[..., :, None] == episode_id[..., None, :]  # [..., T, T]
    return jnp.concatenate([memory, causal & same_episode], axis=-1)


class CriticOutput(NamedTuple):
    value: chex.Array  # [..., T] V(s*_t) (V(s_t) for the plain critic)
    alpha: Optional[chex.Array]  # [..., T, K] row t: attention of step t over the keys; None if plain
    attended_state: chex.Array  # [..., T, H] s*_t (= s_t for the plain critic)


class Critic(nn.Module):
    """State-value critic over the states of one episode.

    `attention=False` (A3C baseline): value = MLP(s_t).
    `attention=True` (ForeSIT, Eq. 3-4): for every step t at once (causal, masked),
      alpha_t = softmax_j( q(s_t) . k(s_j) / sqrt(t+1) ), j = 0..t valid steps of the episode,
      s*_t = sum_j alpha_tj v(s_j) + s_t,  value_t = MLP(s*_t).
    q, k: linear `attention_size`; v: linear to the state size (for the residual), its
    kernel lecun-normal like every other layer's, or zeros (`zero_value_init`,
    `Config.attention_value_init`): then s*_t = s_t at initialisation and the critic starts
    as the plain one. `key_gradient=False` (`Config.attention_key_gradient='stopped'`):
    k and v read the states without gradient, so the value loss reaches the states through
    the query and the residual alone (the memory of earlier windows never carries any).

    Call with `states [..., T, H]` whose index 0 is the episode's first state (t in
    sqrt(t+1) is the position), and `valid [..., T]` (1 on the episode's steps): the keys
    are the states themselves, masked causally. Packed windows (episodes back to back,
    an episode begun in an earlier window) pass the keys, the mask and each step's
    position in its episode explicitly: `keys [..., K, H]`, `key_mask [..., T, K]`
    (see `window_attention_mask`), `positions [..., T]` (t of sqrt(t+1)).
    """

    attention: bool = True
    attention_size: int = 512
    value_hidden: int = 256
    zero_value_init: bool = False
    key_gradient: bool = True

    @nn.compact
    def __call__(
        self,
        states: chex.Array,
        valid: chex.Array,
        keys: Optional[chex.Array] = None,
        key_mask: Optional[chex.Array] = None,
        positions: Optional[chex.Array] = None,
    ) -> CriticOutput:
        chex.assert_equal_shape_prefix([states, valid], valid.ndim)
        chex.assert_rank(states, valid.ndim + 1)
        value_head = ValueHead(self.value_hidden, name="value_head")
        if not self.attention:
            return CriticOutput(value_head(states), None, states)

        num_steps, state_size = states.shape[-2:]
        if keys is None:
            keys, key_mask = states, causal_episode_mask(valid)
        if positions is None:
            positions = jnp.arange(num_steps)
        query = Dense(self.attention_size, name="query")(states)  # [..., T, Q]
        if not self.key_gradient:
            keys = jax.lax.stop_gradient(keys)
        key = Dense(self.attention_size, name="key")(keys)  # [..., K, Q]
        init = nn.initializers.zeros_init() if self.zero_value_init else nn.initializers.lecun_normal()
        value = Dense(state_size, kernel_init=init, name="value")(keys)  # [..., K, H]
        scale = jnp.sqrt(positions.astype(states.dtype) + 1.0)  # [..., T] sqrt(t+1)
        scores = jnp.einsum("...tq,...jq->...tj", query, key) / scale[..., None]  # [..., T, K]
        alpha = masked_softmax(scores, key_mask)  # [..., T, K]
        attended = jnp.einsum("...tj,...jh->...th", alpha, value) + states  # [..., T, H]
        return CriticOutput(value_head(attended), alpha, attended)


class ImaginationNet(nn.Module):
    """f_w: [s_0 : g_tau] -> imagined sub-goal state, 6 fully-connected tanh layers.

    Widths `layer_sizes` (default 512, 256, 64, 256, 512, 512): a bottleneck of 64
    (the sub-goal structure is assumed low-dimensional, Section 4.3) and an output of
    the LSTM size; tanh everywhere, so the output lies in (-1, 1) like the LSTM's h.
    """

    layer_sizes: Sequence[int] = (512, 256, 64, 256, 512, 512)  # Config.imagination_layer_sizes

    @nn.compact
    def __call__(self, s_0: chex.Array, goal: chex.Array) -> chex.Array:
        x = jnp.concatenate([s_0, goal], axis=-1)  # [..., H + D]
        for i, size in enumerate(self.layer_sizes):
            x = jnp.tanh(Dense(size, name=f"layer_{i}")(x))
        return x  # [..., layer_sizes[-1]]


class EncoderInputs(NamedTuple):
    """What the encoder reads at each step, time-major: leaves `[T, ..., ...]`."""

    obs: Any  # observation dict, leaves [T, ..., ...]
    prev_action_probs: chex.Array  # [T, ..., A] (zeros at an episode's first step)
    imagined: Optional[chex.Array] = None  # [T, ..., H] i_tau for the encoder (imagination_input='encoder'), else None


class ActorCritic(nn.Module):
    """theta (encoder + policy) and omega (critic) under one parameter tree.

    Methods (use with `apply(params, ..., method="encode")` etc.):
      encode(carry, inputs: EncoderInputs [T, ...], first [T, ...], kernels, gate_offsets)
        -> (carry, states [T, ..., H]): acting at T = 1, the loss over a window, the
        bootstrap and the goal view's latent at T = 1
      heads(states, imagined) -> logits [..., A]: the policy on [s_t : i_tau]
      critic(states [..., T, H], valid [..., T]) -> CriticOutput
      lstm_kernels(update) -> the encoder LSTM's kernels (foresit_jax.lstm), made once per
        acting window, outside its loop, and adapted by the maml base
      encoder_features(obs, prev_action_probs, imagined) -> the LSTM's input [..., F]
        (the maml base's low-rank update reads it)
      interaction_loss(inputs) -> the maml base's L_phi
    `__call__(carry, obs, prev_action_probs, imagined)` -> (carry, s_t, logits, value): one
    step through flax's own LSTM cell, for `init`, and the reference the split form is
    tested against.

    `imagination_input` (`Config.imagination_input`): where i_tau enters: 'head' and 'mlp'
    give it to the policy head (linear, or a two-layer MLP of `value_hidden` units, which
    the bases get too), 'encoder' to the encoder (`imagination_features` = the target's
    embedding width). `EncoderInputs.imagined` is the encoder's i_tau; `heads` drops its
    `imagined` where the head takes none; `__call__` routes its one `imagined` to
    whichever takes it.
    """

    num_actions: int = 6
    hidden_size: int = 512
    use_imagination: bool = True
    attention_critic: bool = True
    attention_size: int = 512
    value_hidden: int = 256
    linear_value_head: bool = False
    imagination_input: str = "head"
    zero_value_init: bool = False
    key_gradient: bool = True
    object_graph: Optional[nn.Module] = None
    learned_loss: Optional[nn.Module] = None

    @property
    def imagination_in_encoder(self) -> bool:
        return self.use_imagination and self.imagination_input == "encoder"

    def setup(self):
        # i_tau is embedded as wide as the target it sits beside.
        features = Encoder.target_features if self.imagination_in_encoder else 0
        self.encoder = Encoder(
            hidden_size=self.hidden_size, imagination_features=features, object_graph=self.object_graph
        )
        policy_hidden = self.value_hidden if self.imagination_input == "mlp" else 0
        self.policy = PolicyHead(
            self.num_actions, self.use_imagination and not self.imagination_in_encoder, policy_hidden
        )
        value_hidden = 0 if self.linear_value_head else self.value_hidden
        self.value_critic = Critic(
            self.attention_critic, self.attention_size, value_hidden, self.zero_value_init, self.key_gradient
        )

    def encode(
        self,
        carry: LSTMCarry,
        inputs: EncoderInputs,
        first: chex.Array,
        kernels: Optional[LSTMKernels] = None,
        gate_offsets: Optional[chex.Array] = None,
    ) -> tuple[LSTMCarry, chex.Array]:
        """The encoder over T steps, time-major -> (the carry after them, states
        `[T, ..., H]`). The encoder up to the LSTM's input gates needs no carry, so it runs
        over all the steps at once (a few large matmuls instead of T small ones); then the
        LSTM's recurrence, step by step, the carry zeroed before each step that begins an
        episode (`first` `[T, ...]` bool). `kernels`: the LSTM's (`lstm_kernels`, made once
        per acting window, outside its loop; None: this parameter tree's). `gate_offsets`
        `[T, ..., 4H]`: added to the input gates (the maml base's zeros, whose gradient is
        the pre-activations'; None: none)."""
        if kernels is None:
            kernels = self.lstm_kernels()
        size = first.size

        def flat(x):  # [T, ..., ...] -> [T * ..., ...]
            return x.reshape((size,) + x.shape[first.ndim :])

        imagined = None if inputs.imagined is None else flat(inputs.imagined)
        features = self.encoder.features(jax.tree.map(flat, inputs.obs), flat(inputs.prev_action_probs), imagined)
        gates = self.encoder.lstm.input_gates(features, kernels)
        gates = gates.reshape(first.shape + gates.shape[-1:])  # [T, ..., 4H]
        if gate_offsets is not None:
            gates = gates + gate_offsets
        if first.shape[0] == 1:  # one step (acting): no loop
            carry, s_t = self.encoder.lstm.step(kernels, reset_carry(first[0], carry), gates[0])
            return carry, s_t[None]
        return self.encoder.lstm.unroll(kernels, carry, gates, first)

    def heads(self, states: chex.Array, imagined: Optional[chex.Array] = None) -> chex.Array:
        """pi(. | s_t, i_tau) logits `[..., A]` of states `[..., H]`; `imagined` (the i_tau
        of each state) is dropped where the head takes none (no imagination, or i_tau in
        the encoder)."""
        return self.policy(states, imagined if self.policy.use_imagination else None)

    def encoder_features(
        self, obs: Mapping[str, chex.Array], prev_action_probs: chex.Array, imagined: Optional[chex.Array] = None
    ) -> chex.Array:
        """The encoder up to the LSTM's input `[..., F]` (see `Encoder.features`)."""
        return self.encoder.features(obs, prev_action_probs, imagined)

    def lstm_kernels(self, update: Optional[LowRankUpdate] = None) -> LSTMKernels:
        """The encoder LSTM's parameters as the concatenated kernels of its split form
        (`foresit_jax.lstm.EncoderLSTM`: input gates for any number of steps at once, then
        the recurrent step), which `encode` runs instead of calling the cell; `update`: a
        low-rank change of them (the maml base's adapted kernels) or None."""
        return self.encoder.lstm.kernels(update)

    def critic(self, states: chex.Array, valid: chex.Array, keys=None, key_mask=None, positions=None) -> CriticOutput:
        return self.value_critic(states, valid, keys, key_mask, positions)

    def interaction_loss(self, inputs: chex.Array) -> chex.Array:
        """The maml base's learned loss L_phi over one segment of [s_t : pi_t] (see
        `foresit_jax.learned_loss.LearnedLoss`); only with `learned_loss` set."""
        if self.learned_loss is None:
            raise ValueError("ActorCritic.interaction_loss needs the maml base's learned_loss module")
        return self.learned_loss(inputs)

    def __call__(self, carry, obs, prev_action_probs, imagined=None):
        """One step through flax's own cell -> (carry, s_t, logits, value); `imagined` goes to
        the encoder or to the head, by `imagination_input`."""
        carry, s_t = self.encoder(carry, obs, prev_action_probs, imagined if self.imagination_in_encoder else None)
        logits = self.heads(s_t, imagined)
        out = self.critic(s_t[..., None, :], jnp.ones(s_t.shape[:-1] + (1,), bool))
        if self.learned_loss is not None:  # create phi at init
            segment = jnp.zeros((self.learned_loss.segment, s_t.shape[-1] + logits.shape[-1]), s_t.dtype)
            self.interaction_loss(segment)
        return carry, s_t, logits, out.value


def subgoals_of_rows(keys: chex.Array, alpha: chex.Array, mode: str = "argmax") -> chex.Array:
    """The sub-goal each attention row would select: `keys [..., K, H]`, `alpha [..., R, K]`
    -> `[..., R, H]` (stop-gradient, targets for f_w): the key with the largest weight
    ('argmax', ForeSIT's s_{t*}, first on ties) or the weighted average
    ('attention_average', the `att` ablation). Masked keys carry alpha = 0."""
    chex.assert_equal_shape_prefix([keys, alpha], keys.ndim - 2)
    keys, alpha = jax.lax.stop_gradient((keys, alpha))
    if mode == "argmax":
        index = jnp.argmax(alpha, axis=-1)  # [..., R]
        return jnp.take_along_axis(keys, index[..., None], axis=-2)  # [..., R, H]
    if mode == "attention_average":
        return jnp.einsum("...rk,...kh->...rh", alpha, keys)
    raise ValueError(f"Unknown sub-goal mode {mode!r}; use 'argmax' or 'attention_average'.")


@dataclasses.dataclass(frozen=True, eq=False)
class Networks:
    """What acts, as a record: a Config's networks (`build`) and the Config. The functions
    of `foresit_jax.rollout` act with it; nothing here calls back into them.

    imagine: f_w, `(w, s, goal) -> [..., H]` (`imagination_net.apply`); permute: a
    reordering of the lanes applied to i_tau's inputs when acting (the probe's shuffle of
    i_tau across episodes, `experiments.analysis.probes.shuffled`; None: none). Compared by identity
    (a jitted function built on one is compiled for it alone)."""

    config: Config
    model: ActorCritic
    imagination_net: ImaginationNet
    imagine: Callable
    permute: Optional[Callable] = None
    # The Config's parsed method and its imagination piece, held when the record is made:
    method: Method = dataclasses.field(init=False)
    imagination_variant: ImaginationVariant = dataclasses.field(init=False)

    def __post_init__(self):
        object.__setattr__(self, "method", self.config.pieces)
        object.__setattr__(self, "imagination_variant", self.config.pieces.imagination_variant)

    @property
    def imagination_in_encoder(self) -> bool:
        """Whether i_tau enters the encoder (`Config.imagination_input='encoder'`)."""
        return self.model.imagination_in_encoder

    @property
    def imagination_in_head(self) -> bool:
        """Whether i_tau enters the policy head (and is recorded for the replay)."""
        return self.imagination_variant.uses_imagination and not self.model.imagination_in_encoder

    def init(self, key: chex.PRNGKey, obs: dict) -> tuple[Any, Any]:
        """(theta/omega params, f_w params) from one unbatched observation."""
        k_model, k_imag = jax.random.split(key)
        hidden = self.config.hidden_size
        probs = jnp.zeros((self.config.num_actions,), jnp.float32)
        imagined = jnp.zeros((hidden,), jnp.float32) if self.imagination_variant.uses_imagination else None
        params = self.model.init(k_model, initial_carry((), hidden), obs, probs, imagined)
        w_params = self.imagination_net.init(k_imag, jnp.zeros((hidden,)), obs["target"])
        return params, w_params


def build(config: Config) -> Networks:
    """The networks of `config`: where a method's pieces (flags) become modules."""
    method = config.pieces
    model = ActorCritic(
        # ORG's object-relation graph over the `org` setup's detector features (None: none).
        object_graph=ObjectGraph() if method.encoder_piece.object_graph else None,
        # SAVN's learned interaction loss (the maml base; params["params"]["learned_loss"]).
        learned_loss=LearnedLoss(segment=config.maml_segment) if method.base_piece.adapts_in_episode else None,
        num_actions=config.num_actions,
        hidden_size=config.hidden_size,
        use_imagination=method.imagination_variant.uses_imagination,
        attention_critic=method.attention_critic,
        attention_size=config.attention_size,
        value_hidden=config.value_hidden,
        linear_value_head=config.value_head == "linear",
        imagination_input=config.imagination_input,
        zero_value_init=config.attention_value_init == "zeros",
        key_gradient=config.attention_key_gradient == "full",
    )
    imagination_net = ImaginationNet(config.imagination_layer_sizes)
    return Networks(config, model, imagination_net, imagination_net.apply)
