"""Hyperparameters (a frozen dataclass) and the method registry.

Every method of the paper is a set of flags on one agent (`MethodFlags`), looked up by
name in `METHODS`; `Config.flags` is the looked-up entry. Nothing mutates a config:
use `dataclasses.replace(config, field=value)` for a variant (it re-validates).
"""

from __future__ import annotations

import dataclasses
from typing import Mapping

SETUPS: tuple[str, ...] = ("savn", "org")
SUBGOAL_MODES: tuple[str, ...] = ("argmax", "attention_average")
IMAGINATION_SOURCES: tuple[str, ...] = ("none", "learned", "random")
IMAGINATION_OPTIMIZERS: tuple[str, ...] = ("sgd", "adam")


@dataclasses.dataclass(frozen=True)
class MethodFlags:
    """What a method switches on. A method is one agent with these flags."""

    imagination: str = "none"
    """Source of i_tau: 'none' (policy sees s_t only), 'learned' (f_w + noise, ForeSIT),
    'random' (tanh of Gaussian noise, the `rnd` ablation)."""
    attention_critic: bool = False
    """Value from the attention of Eq. 3-4 (V(s*_t)); False: plain MLP on s_t."""
    subgoal_mode: str = "argmax"
    """What f_w learns to imagine: 'argmax' (s_{t*}, ForeSIT) or 'attention_average'
    (sum_j alpha_j s_j, the `att` ablation)."""
    reimagine_every_k: bool = False
    """The `int` ablation: re-imagine from s_t every `Config.int_interval` steps."""

    @property
    def uses_imagination(self) -> bool:
        return self.imagination != "none"

    @property
    def trains_imagination(self) -> bool:
        """Whether buffers are filled and f_w is trained."""
        return self.imagination == "learned"


_FORESIT = MethodFlags(imagination="learned", attention_critic=True)

METHODS: Mapping[str, MethodFlags] = {
    # SAVN's non-adaptive A3C: LSTM encoder, linear policy on s_t, value MLP on s_t.
    "a3c": MethodFlags(),
    # ForeSIT on A3C: attention critic, sub-goal selection, f_w, noisy i_tau.
    "a3c+foresit": _FORESIT,
    # Table 3 ablations, each ForeSIT with one change.
    "rnd": dataclasses.replace(_FORESIT, imagination="random"),
    "att": dataclasses.replace(_FORESIT, subgoal_mode="attention_average"),
    "int": dataclasses.replace(_FORESIT, reimagine_every_k=True),
}

# Methods of the paper not implemented yet (clearly marked placeholders).
PLANNED_METHODS: Mapping[str, str] = {
    "a3c+maml": "SAVN's self-adaptive meta-learning (inner SGD on a learned interaction loss)",
    "a3c+maml+foresit": "SAVN's self-adaptive meta-learning with ForeSIT",
    "a3c+org": "the object-relation-graph encoder (Encoder.object_graph hook)",
    "a3c+org+foresit": "the object-relation-graph encoder with ForeSIT",
}


def method_flags(name: str) -> MethodFlags:
    """Look up a method. Planned ones raise NotImplementedError, unknown ValueError."""
    if name in METHODS:
        return METHODS[name]
    if name in PLANNED_METHODS:
        raise NotImplementedError(
            f"Method {name!r} ({PLANNED_METHODS[name]}) is not implemented yet; "
            f"implemented: {sorted(METHODS)}."
        )
    raise ValueError(
        f"Unknown method {name!r}; valid names: {sorted(METHODS)} "
        f"(planned: {sorted(PLANNED_METHODS)})."
    )


@dataclasses.dataclass(frozen=True)
class Config:
    """All hyperparameters of one training run (paper values where the paper gives one)."""

    method: str = "a3c+foresit"
    """Method name, a key of METHODS (see `method_flags`)."""
    setup: str = "savn"
    """Environment setup: 'savn' (first setup, 300-d word-vector targets) or 'org'
    (second setup, one-hot targets + detector features)."""

    room_types: tuple[str, ...] = ()
    """Room types to train on (e.g. ('bathroom',) for an easy setting); () for all four."""

    # Training loop (synchronous batched A3C).
    num_lanes: int = 16
    """Parallel env lanes (A3C agents); one episode each per update."""
    num_updates: int = 2000
    """Gradient updates (each on one padded episode per lane)."""
    num_steps: int = 30
    """Padded rollout length T; at least the env's training episode limit (30, SAVN)."""

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
    """Actions: MoveAhead, RotateLeft, RotateRight, LookUp, LookDown, Done."""
    hidden_size: int = 512
    """LSTM hidden units; s_t, i_tau and ŝ_tau have this size."""
    attention_size: int = 512
    """Width of the critic's query and key layers."""
    value_hidden: int = 256
    """Hidden width of the two-layer value MLP."""
    imagination_layer_sizes: tuple[int, ...] = (512, 256, 64, 256, 512, 512)
    """Widths of f_w's 6 tanh layers (bottleneck 64); the last must equal hidden_size."""

    # Imagination (Section 4.3-4.4).
    buffer_size: int = 32
    """M_max: per-lane replay buffer capacity; f_w is trained when it is full."""
    imagination_epochs: int = 5
    """Epoch_max: passes over a full buffer (the paper does not give it)."""
    imagination_optimizer: str = "adam"
    """Lane-local optimiser of f_w: 'sgd' or 'adam' (fresh state per buffer flush)."""
    imagination_lr: float = 1e-3
    """Learning rate beta of f_w (the paper does not give it)."""
    sigma2_max: float = 0.9
    """Maximum imagination-noise variance sigma^2_max (Eq. 7)."""
    success_window: int = 100
    """Episodes in each lane's moving success rate rho."""
    rnd_variance: float = 0.5
    """Variance of z in the `rnd` ablation, i_tau = tanh(z)."""
    int_interval: int = 10
    """K: the `int` ablation re-imagines from s_t every K steps."""

    def __post_init__(self):
        # Keep the config hashable (usable as a jit static argument) if given a list.
        object.__setattr__(self, "imagination_layer_sizes", tuple(self.imagination_layer_sizes))
        object.__setattr__(self, "room_types", tuple(self.room_types))
        self.validate()

    def validate(self) -> None:
        """Raise ValueError (NotImplementedError for planned methods) on bad values."""
        method_flags(self.method)
        if self.setup not in SETUPS:
            raise ValueError(f"setup must be one of {SETUPS}, got {self.setup!r}.")
        if self.imagination_optimizer not in IMAGINATION_OPTIMIZERS:
            raise ValueError(
                f"imagination_optimizer must be one of {IMAGINATION_OPTIMIZERS}, "
                f"got {self.imagination_optimizer!r}."
            )
        for name in (
            "num_lanes", "num_updates", "num_steps", "num_actions", "hidden_size",
            "attention_size", "value_hidden", "buffer_size", "imagination_epochs",
            "success_window", "int_interval",
        ):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int):
                raise ValueError(f"{name} must be an int, got {value!r} ({type(value).__name__}).")
            if value < 1:
                raise ValueError(f"{name} must be >= 1, got {value}.")
        for name in ("learning_rate", "imagination_lr", "max_grad_norm", "rnd_variance"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}.")
        if not 0.0 < self.gamma <= 1.0:
            raise ValueError(f"gamma must be in (0, 1], got {self.gamma!r}.")
        if not 0.0 <= self.gae_lambda <= 1.0:
            raise ValueError(f"gae_lambda must be in [0, 1], got {self.gae_lambda!r}.")
        for name in ("entropy_coef", "value_coef", "sigma2_max"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}.")
        sizes = self.imagination_layer_sizes
        if len(sizes) < 1 or any(isinstance(s, bool) or not isinstance(s, int) or s < 1 for s in sizes):
            raise ValueError(f"imagination_layer_sizes must be positive ints, got {sizes!r}.")
        if sizes[-1] != self.hidden_size:
            raise ValueError(
                f"imagination_layer_sizes[-1] ({sizes[-1]}) must equal hidden_size "
                f"({self.hidden_size}): f_w imagines a state."
            )

    @property
    def flags(self) -> MethodFlags:
        """The method's switches (from METHODS)."""
        return method_flags(self.method)

    @property
    def num_episodes(self) -> int:
        """Training episodes in the whole run (one per lane per update)."""
        return self.num_lanes * self.num_updates
