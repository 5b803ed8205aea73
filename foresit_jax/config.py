"""Hyperparameters of one training run (a frozen dataclass).

`Config.method` names a composition of pieces (`foresit_jax.methods`); `Config.pieces`
is the parsed `Method`, validated with the setup and the gradient path. Nothing mutates
a config: use `dataclasses.replace(config, field=value)` for a variant (it re-validates).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import typing
from typing import Optional

from foresit_jax.methods import GRADIENTS, ROLLOUTS, Method, parse_method

SETUPS: tuple[str, ...] = ("savn", "org")
LAYOUTS: tuple[str, ...] = ("room", "house")
IMAGINATION_OPTIMIZERS: tuple[str, ...] = ("sgd", "adam")
IMAGINATION_INPUTS: tuple[str, ...] = ("head", "encoder", "mlp")
EVALUATION_NOISES: tuple[str, ...] = ("training_end", "off")
VALUE_HEADS: tuple[str, ...] = ("mlp", "linear")
IMAGINATION_NOISES: tuple[str, ...] = ("output", "input")
ATTENTION_VALUE_INITS: tuple[str, ...] = ("lecun", "zeros")
ATTENTION_KEY_GRADIENTS: tuple[str, ...] = ("full", "stopped")
# The auxiliary training targets (`foresit_jax.targets`); "none": no target.
AUX_TARGETS: tuple[str, ...] = ("none", "compass", "goal_view", "success")
# The environment's actions (`envs.catalog.ACTIONS`, written again here: importing envs loads
# jax, and a Config is jax-free; tests/experiments/test_user_checks.py holds the two equal).
ACTIONS: tuple[str, ...] = ("MoveAhead", "RotateLeft", "RotateRight", "LookUp", "LookDown", "Done")


@dataclasses.dataclass(frozen=True)
class Config:
    """All hyperparameters of one training run (paper values where the paper gives one)."""

    method: str = "a3c+foresit"
    """Method: '+'-joined pieces, e.g. 'a3c', 'a3c+foresit', 'a3c+rnd' (see `foresit_jax.methods`)."""
    setup: str = "savn"
    """Environment setup: 'savn' (first setup, 300-d word-vector targets) or 'org'
    (second setup, one-hot targets + detector features)."""

    room_types: tuple[str, ...] = ()
    """Room types to train on (e.g. ('bathroom',) for an easy setting); () for all four.
    In houses: the targets that stand in rooms of these types."""
    layout: str = "room"
    """Scenes: 'room' (single AI2-THOR-like rooms, as the paper's) or 'house' (houses of 2-4
    rooms joined by doorways, `envs.houses`: paths about 3x longer, the target in another
    room than the start in 80% of the episodes, time limits 60 / 300)."""
    priors: bool = False
    """Scenes with the regularities of real homes (`envs.priors`): furniture of distinct
    kinds seen as their own classes, each target placed by relations to furniture and to
    other targets, houses' rooms in adjacent pairs, related savn word vectors. False:
    GridNav's default scenes, where every target stands uniformly at random."""
    perception_range: Optional[float] = None
    """A perception range, in cells (0.25 m): object pixels deeper than it show one
    'unresolved object' class, so a far target is seen as some object and its anchor
    furniture as what it is (`envs.GridNav`'s `perception_range`; docs/foresight.md,
    "Levers"). None, the default: every object resolved at any depth."""
    progress_reward: float = 0.0
    """Reward shaping (a deviation from the paper's reward, which is +5 on success and
    -0.01 a step): each step also earns w (d_t - d_{t+1}), d the oracle's actions to
    success (`envs.gridnav.EnvParams.progress_reward`; AllenAct's ObjectNav reward with its
    `shaping_weight`). 0 is the paper's reward. The house preset uses 0.1: in houses the
    paper's reward lets a3c learn to give up at the start (docs/houses.md)."""

    # Training loop (synchronous batched A3C).
    rollout: str = "packed"
    """'packed': every lane steps continuously through windows of `num_steps` (A3C's
    n-step window), episodes back to back, an episode cut at a window's edge carried into
    the next update and bootstrapped (Eq. 8). 'episodes': SAVN's whole-episode updates,
    every lane reset at each update and run for one episode padded to `num_steps` (the
    reference; `num_steps` must be at least the training time limit)."""
    gradient: str = "replay"
    """How the loss's gradient is computed: 'replay' (act without gradients, then re-run
    the modules over the recorded inputs, the feed-forward part batched over the whole
    window) or 'through_rollout' (differentiate through the acting scan; the reference).
    Equal up to float rounding; each method declares which it supports."""
    num_lanes: int = 16
    """Parallel env lanes (A3C agents)."""
    num_updates: int = 2000
    """Gradient updates (each on one window of `num_steps` steps per lane)."""
    num_steps: int = 30
    """Window length T (steps per lane per update)."""

    # A3C loss (Eq. 8-9) and optimiser.
    gamma: float = 0.99
    """Discount factor."""
    gae_lambda: float = 1.0
    """GAE lambda (SAVN's tau)."""
    entropy_coef: float = 0.01
    """Entropy bonus weight beta_H."""
    value_coef: float = 0.5
    """Weight of the value loss in the total loss."""
    learning_rate: float = 1e-4
    """Adam learning rate of theta and omega."""
    max_grad_norm: float = 50.0
    """Global gradient-norm clip (A3C convention; the paper gives none)."""

    # Networks.
    num_actions: int = 6
    """Actions: MoveAhead, RotateLeft, RotateRight, LookUp, LookDown, Done (the environment's
    six; no other count is accepted)."""
    hidden_size: int = 512
    """LSTM hidden units; s_t, i_tau and ŝ_tau have this size."""
    attention_size: int = 512
    """Width of the critic's query and key layers."""
    value_hidden: int = 256
    """Hidden width of the two-layer value MLP."""
    value_head: str = "mlp"
    """'mlp': V is a two-layer MLP (`value_hidden` units, ReLU), as the paper writes it for
    the attended state (Section 5.2), here for every method; 'linear': one dense layer, SAVN's
    critic (models/basemodel.py, Linear(512, 1)), whose A3C row the paper's table copies
    (ORG's two stacked linear layers are linear too). The attention critic's s*_t feeds
    the same head. docs/deviations.md."""
    attention_value_init: str = "lecun"
    """Initial kernel of the attention critic's v in s*_t = sum_j alpha_j v(s_j) + s_t
    (Eq. 3): 'lecun' (lecun-normal, as every other layer; the paper gives none), whose
    sum adds a term as large as s_t itself to the value head's input at the start, or
    'zeros' (s*_t = s_t at initialisation: the critic starts as the plain one and learns
    what to add). docs/mechanism.md (Study 3) measures the two."""
    attention_key_gradient: str = "full"
    """Which of the attention critic's inputs carry the value loss's gradient into the
    encoder (the paper trains omega and theta on one loss, Eq. 9, and says no more): 'full'
    (every state it reads: the query s_t, and the keys and values k(s_j), v(s_j) of the
    episode's earlier states), or 'stopped' (a deviation: the keys and values read the
    states without gradient, so the critic's gradient reaches the encoder through s_t alone,
    its query and residual, as the plain critic's does through its MLP). A candidate cause
    of the attention critic's cost (docs/mechanism.md)."""
    imagination_layer_sizes: tuple[int, ...] = (512, 256, 64, 256, 512, 512)
    """Widths of f_w's tanh layers, one layer per width (`networks.ImaginationNet`): the
    paper's 6, with a bottleneck of 64; any number from one up, the last equal to
    hidden_size (f_w imagines a state)."""

    # Imagination (Section 4.3-4.4).
    buffer_size: int = 32
    """M_max: per-lane replay buffer capacity; f_w is trained when it is full."""
    imagination_epochs: int = 5
    """Epoch_max: passes over a full buffer (the paper does not give it)."""
    imagination_optimizer: str = "adam"
    """Lane-local optimiser of f_w: 'sgd' or 'adam' (fresh state per buffer flush)."""
    imagination_lr: float = 1e-3
    """Learning rate beta of f_w (the paper does not give it)."""
    imagination_noise: str = "output"
    """Where the exploration noise N(0, sigma^2 I) of Eq. 7's variance enters: 'output', on
    f_w's output, i_tau = f_w([s_0 : g_tau]) + eta (Eq. 6, the spec); 'input', on f_w's input,
    i_tau = f_w([s_0 : g_tau] + eta), as Algorithm 1 writes it (the two disagree)."""
    imagination_batch: int = 1
    """Items per f_w step within a full buffer, in buffer order (their mean loss): 1, one
    item a step, is Algorithm 1's; it must divide buffer_size."""
    sigma2_max: float = 0.9
    """Maximum imagination-noise variance sigma^2_max (Eq. 7). The paper's 0.9 keeps most
    of i_tau's variance noise at this budget; 0.1 (a deviation) keeps the signal above it
    (docs/mechanism.md, Study 3, measures both)."""
    success_window: int = 100
    """Episodes in each lane's moving success rate rho."""
    rnd_variance: float = 0.5
    """Variance of z in the `rnd` ablation, i_tau = tanh(z)."""
    int_interval: int = 10
    """K: the `int` ablation re-imagines from s_t every K steps."""
    imagination_input: str = "head"
    """Where i_tau enters the policy. The paper gives pi_theta(a_t | s_t, g_tau, i_tau)
    (Eq. 6) and "we condition the policy on the imagined sub-goal state" (Section 4.4),
    and its policy is "a single fully-connected layer" (Section 5.2); it does not say how
    s_t and i_tau meet. 'head' (the literal reading, the default): the linear policy head
    over [s_t : i_tau]; i_tau is constant over an episode, so it can only add one fixed
    offset to the logits of the whole episode. 'encoder': i_tau joins the encoder's
    input beside g_tau (embedded to `target_features` like the target, ReLU, tiled over
    the view grid before the 1x1 convolution) at every step after the episode's first
    (zeros at the first: i_tau is imagined from s_0, the first step's output), and the
    head sees s_t alone, so the recurrent state can relate what it imagines to what it
    sees, as SAVN feeds its target. 'mlp': the policy head is a two-layer MLP (ReLU,
    `value_hidden` units) over [s_t : i_tau], which can relate the two inside one step;
    the bases get the same MLP over s_t with this value, so a pair changes one thing.
    Methods without imagination ignore 'head' and 'encoder'."""
    evaluation_noise: str = "training_end"
    """The imagination noise at evaluation: 'training_end' (the lanes' mean Eq. 7
    variance when training stopped: the imagination the policy was trained with) or
    'off' (i_tau = f_w([s_0 : g_tau]) exactly). The paper does not say."""

    # Imagination as a training target (`foresit_jax.imagination`'s targets): nothing of it acts.
    aux_target: str = "none"
    """An auxiliary target that a linear head on s_t learns to predict at every valid step,
    in training only (its parameters are a tree of their own; the agent that acts and is
    evaluated is the base's): 'compass' (the bearing and distance of the nearest target
    cell, a privileged label in training), 'goal_view' (the agent's latent of the episode's
    goal view, a privileged label in training), 'success' (the agent's own state at the
    step its episode succeeded, for the earlier steps of that episode in the same window;
    not privileged), or 'none'."""
    aux_weight: float = 1.0
    """lambda: the auxiliary loss's weight beside the actor-critic loss (ignored without a
    target; 0 trains the head and leaves the agent the base's)."""
    aux_permute: bool = False
    """The target's content control (docs/plans/imagination_targets.md, stage 2): each lane
    learns the labels of the lane before it (the window's labels and their mask rolled by
    one lane), so the labels keep their distribution and lose their relation to the lane's
    own states. Needs a target and at least 2 lanes."""

    # The maml base (SAVN, `foresit_jax.maml`): SAVN's values.
    maml_segment: int = 6
    """Steps between inner updates, and the learned loss's segment length (SAVN's num_steps)."""
    maml_inner_updates: int = 4
    """Most inner updates per episode (SAVN's gradient_limit): after steps 6, 12, 18, 24."""
    maml_inner_lr: float = 1e-4
    """Inner SGD step size on the learned loss (SAVN's inner_lr)."""
    maml_first_order: bool = False
    """Stop the gradient through the inner gradient (first-order MAML); off: exact second order.
    First order leaves the learned loss's parameters at their initial values: they get
    their gradient only through the inner gradient."""

    def __post_init__(self):
        # Plain Python values, so that the config stays hashable (a jit static argument) and
        # JSON-able: numpy scalars as Python's, a list (or a numpy array) for a tuple as a
        # tuple, one room type's name as a tuple of it (as `envs.make` reads it).
        for name, hint in field_types().items():
            value = getattr(self, name)
            if typing.get_origin(hint) is tuple:
                if isinstance(value, str) and typing.get_args(hint)[0] is str:
                    value = (value,)
                elif _is_numpy(value) and getattr(value, "ndim", 0) > 0:
                    value = value.tolist()
                if isinstance(value, (list, tuple)):
                    value = tuple(_plain(v) for v in value)
            else:
                value = _plain(value)
            object.__setattr__(self, name, value)
        self.validate()

    def validate(self) -> None:
        """Raise ValueError on bad values. The method is parsed here, once (`pieces`)."""
        for name, hint in field_types().items():  # each field's type first: a str for a bool is no bool
            check_type(name, hint, getattr(self, name))
        pieces = parse_method(self.method)
        if self.setup not in SETUPS:
            raise ValueError(f"setup must be one of {SETUPS}, got {self.setup!r}.")
        if self.layout not in LAYOUTS:
            raise ValueError(f"layout must be one of {LAYOUTS}, got {self.layout!r}.")
        # The same check as envs.gridnav.check_perception_range, written again here because
        # importing envs loads jax, and a Config is jax-free (tests/structure/test_structure.py).
        if self.perception_range is not None and (
            isinstance(self.perception_range, bool)
            or not isinstance(self.perception_range, (int, float))
            or not 0 < self.perception_range < math.inf
        ):
            raise ValueError(
                f"perception_range must be None (off) or a positive number of cells, got {self.perception_range!r}."
            )
        if pieces.required_setup not in (None, self.setup):
            raise ValueError(
                f"method {self.method!r} needs setup {pieces.required_setup!r} (its {pieces.encoder!r} "
                f"encoder reads the detector features), got setup {self.setup!r}."
            )
        for name, valid, supported in (
            ("rollout", ROLLOUTS, pieces.rollouts),
            ("gradient", GRADIENTS, pieces.gradients),
        ):
            value = getattr(self, name)
            if value not in valid:
                raise ValueError(f"{name} must be one of {valid}, got {value!r}.")
            if value not in supported:
                needs = ", ".join(f"{k}={v!r}" for k, v in pieces.required_config.items())
                raise ValueError(
                    f"method {self.method!r} supports {name} {supported}, not {value!r} (it needs {needs})."
                )
        for name, valid in (
            ("imagination_input", IMAGINATION_INPUTS),
            ("evaluation_noise", EVALUATION_NOISES),
            ("value_head", VALUE_HEADS),
            ("imagination_noise", IMAGINATION_NOISES),
            ("attention_value_init", ATTENTION_VALUE_INITS),
            ("attention_key_gradient", ATTENTION_KEY_GRADIENTS),
        ):
            if getattr(self, name) not in valid:
                raise ValueError(f"{name} must be one of {valid}, got {getattr(self, name)!r}.")
        if pieces.imagination_variant.reads_goal_view and self.imagination_noise != "output":
            raise ValueError(
                f"method {self.method!r} takes i_tau from the goal view, not from f_w: its noise is "
                "Eq. 6's, on i_tau; drop imagination_noise (or set it to 'output')."
            )
        if pieces.imagination_variant.reads_cue and (self.sigma2_max != 0 or self.imagination_noise != "output"):
            raise ValueError(
                f"method {self.method!r} gives the policy an exact privileged cue, without Eq. 7's noise: "
                "set sigma2_max=0 (and leave imagination_noise at 'output')."
            )
        if self.aux_target not in AUX_TARGETS:
            raise ValueError(f"aux_target must be one of {AUX_TARGETS}, got {self.aux_target!r}.")
        if self.aux_target != "none":
            if pieces.base_piece.adapts_in_episode or self.gradient != "replay":
                raise ValueError(
                    f"aux_target {self.aux_target!r} needs the replay loss (gradient='replay'), which method "
                    f"{self.method!r} with gradient {self.gradient!r} does not compute: use the a3c base, or "
                    "aux_target='none'."
                )
            if pieces.imagination_variant.reads_goal_view or pieces.imagination_variant.reads_cue:
                raise ValueError(
                    f"aux_target {self.aux_target!r} with method {self.method!r}: a method that reads a "
                    "privileged input takes no training target (their wrappers would stack); choose one."
                )
        if self.aux_permute is True and (self.aux_target == "none" or self.num_lanes < 2):
            raise ValueError(
                f"aux_permute=True permutes a target's labels across lanes: it needs aux_target (got "
                f"{self.aux_target!r}) and at least 2 lanes (got num_lanes={self.num_lanes})."
            )
        if self.imagination_optimizer not in IMAGINATION_OPTIMIZERS:
            raise ValueError(
                f"imagination_optimizer must be one of {IMAGINATION_OPTIMIZERS}, got {self.imagination_optimizer!r}."
            )
        for name in (
            "num_lanes",
            "num_updates",
            "num_steps",
            "num_actions",
            "hidden_size",
            "attention_size",
            "value_hidden",
            "buffer_size",
            "imagination_epochs",
            "imagination_batch",
            "success_window",
            "int_interval",
            "maml_segment",
        ):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int):
                raise ValueError(f"{name} must be an int, got {value!r} ({type(value).__name__}).")
            if value < 1:
                raise ValueError(f"{name} must be >= 1, got {value}.")
        if self.buffer_size % self.imagination_batch:
            raise ValueError(
                f"imagination_batch ({self.imagination_batch}) must divide buffer_size ({self.buffer_size}): "
                "a full buffer is split into steps of that many items"
            )
        if (
            isinstance(self.maml_inner_updates, bool)
            or not isinstance(self.maml_inner_updates, int)
            or self.maml_inner_updates < 0
        ):
            raise ValueError(f"maml_inner_updates must be an int >= 0, got {self.maml_inner_updates!r}.")
        for f in dataclasses.fields(self):  # inf or NaN breaks a run and cannot be saved in strict JSON
            value = getattr(self, f.name)
            if isinstance(value, float) and not math.isfinite(value):
                raise ValueError(f"{f.name} must be a finite number, got {value!r}.")
        for name in ("learning_rate", "imagination_lr", "max_grad_norm", "rnd_variance", "maml_inner_lr"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}.")
        if not 0.0 < self.gamma <= 1.0:
            raise ValueError(f"gamma must be in (0, 1], got {self.gamma!r}.")
        if not 0.0 <= self.gae_lambda <= 1.0:
            raise ValueError(f"gae_lambda must be in [0, 1], got {self.gae_lambda!r}.")
        for name in ("entropy_coef", "value_coef", "sigma2_max", "progress_reward", "aux_weight"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}.")
        if self.num_actions != len(ACTIONS):
            raise ValueError(
                f"num_actions must be {len(ACTIONS)}, the environment's actions ({', '.join(ACTIONS)}), got "
                f"{self.num_actions}: the agent's policy has one output per action; leave num_actions out."
            )
        sizes = self.imagination_layer_sizes
        if len(sizes) < 1:
            raise ValueError(
                "imagination_layer_sizes must give at least one width: f_w is one tanh layer per width, the last "
                f"of hidden_size units (the paper's 6: {Config.imagination_layer_sizes}), got ()."
            )
        if any(s < 1 for s in sizes):
            raise ValueError(f"imagination_layer_sizes must be positive ints, got {sizes!r}.")
        if sizes[-1] != self.hidden_size:
            raise ValueError(
                f"imagination_layer_sizes[-1] ({sizes[-1]}) must equal hidden_size "
                f"({self.hidden_size}): f_w imagines a state."
            )
        object.__setattr__(self, "_pieces", pieces)  # not a field: equality and hashing ignore it

    @property
    def pieces(self) -> Method:
        """The method's pieces (base, encoder, critic, imagination), parsed from `method`
        once, when the config was made."""
        return self._pieces

    @property
    def frames_per_update(self) -> int:
        """Environment steps per update (all lanes)."""
        return self.num_lanes * self.num_steps


@functools.cache
def field_types() -> dict[str, object]:
    """Each Config field's type (`typing.get_type_hints`), in the fields' order."""
    hints = typing.get_type_hints(Config)
    return {f.name: hints[f.name] for f in dataclasses.fields(Config)}


def _is_numpy(value) -> bool:
    return type(value).__module__ == "numpy"


def _plain(value):
    """A numpy scalar (np.float32(1e-3), np.int64(5), np.bool_(True), a 0-d array) as the
    Python value it holds; anything else as it is."""
    if _is_numpy(value) and getattr(value, "ndim", None) == 0 and hasattr(value, "item"):
        return value.item()
    return value


_NAMES = {bool: "a bool", int: "an int", float: "a float", str: "a str"}


def check_type(name: str, hint, value) -> None:
    """A ValueError where `value` is not of the field `name`'s type `hint`: a bool is a bool
    (not 'False', not 0), an int an int (not a bool, not 5.0), a float a number (an int is
    one; not '1e-3'), a str a str, a tuple a tuple of its type (`__post_init__` made lists
    tuples), an Optional one of them or None."""
    args = typing.get_args(hint)
    if typing.get_origin(hint) is typing.Union:  # Optional[X]
        if value is None:
            return
        (hint,) = [a for a in args if a is not type(None)]
        want = f"{_NAMES[hint]} or None"
    elif typing.get_origin(hint) is tuple:
        what = {str: "strs", int: "ints"}[args[0]]
        if not isinstance(value, tuple):
            raise ValueError(f"{name} must be a tuple of {what}, got {value!r} ({type(value).__name__}).")
        for item in value:
            if not _is_a(item, args[0]):
                raise ValueError(
                    f"{name} must be a tuple of {what}, got {value!r}, which holds {item!r} ({type(item).__name__})."
                )
        return
    else:
        want = _NAMES[hint]
    if not _is_a(value, hint):
        raise ValueError(f"{name} must be {want}, got {value!r} ({type(value).__name__}).")


def _is_a(value, kind) -> bool:
    if kind is bool:
        return isinstance(value, bool)
    if isinstance(value, bool):
        return False
    return isinstance(value, (int, float) if kind is float else kind)
