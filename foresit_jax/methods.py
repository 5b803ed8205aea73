"""Methods as compositions of small named pieces (NAVIX style).

A method is a base learner x an encoder x a critic x an imagination variant:

* base: `a3c` (SAVN's non-adaptive A3C) or `maml` (SAVN's self-adaptive learner:
  inner SGD on a learned interaction loss inside every episode, `foresit_jax.maml`);
* encoder: `plain` (SAVN's observation encoder) or `org` (ORG's object-relation graph on
  the `org` setup's detector features, `foresit_jax.org`);
* critic: `plain` (an MLP on s_t, the bases' value head) or `attention` (Eq. 3-4: the
  MLP on s*_t = sum_j alpha_j v(s_j) + s_t over the episode's states so far). The piece
  `critic` names the attention critic, `plaincritic` the plain one; without either a method
  gets its imagination's default (attention for every imagination variant, as the paper's
  rows have it; plain without imagination), so `a3c+critic` is the attention critic with
  no imagination and `a3c+foresit+plaincritic` ForeSIT without it;
* imagination: `none`, `foresit` (Sections 4.2-4.4), or a Table 3 ablation: `rnd`
  (i_tau = tanh(z)), `att` (imagine the attention-weighted average state), `int`
  (re-imagine from s_t every K steps); and `oracle`, a privileged diagnostic, never a
  method: i_tau is the agent's own latent of its episode's goal view (the view where the
  oracle's shortest path ends, `envs.wrappers.GoalViewWrapper`), the ceiling of a
  perfect imagination of success (docs/ceiling.md).

Which state f_w learns to imagine depends on the critic: with the attention critic the
sub-goal is s_{t*}, t* the argmax of the Done step's attention row (Section 4.2); the plain
critic has no attention, and the sub-goal is then the Done step's own state (the paper's
footnote 1: "a sub-goal state could potentially be the final goal state"). `att` imagines
the attention-weighted average, so it needs the attention critic.

Names are '+'-joined pieces in any order, the base defaulting to a3c (and `a3c+maml`
naming the maml base, A3C trained by MAML, as the paper does): `a3c`,
`a3c+foresit`, `a3c+org+foresit`, `a3c+maml+foresit`, `org+rnd`, `a3c+critic`; the Table 3
names alone (`rnd`, `att`, `int`) mean `a3c+rnd` etc. `parse_method` turns a name into a `Method`;
`Config` validates it with the setup. Each piece is a small record of flags (`Base`: whether
the parameters adapt inside an episode; `Encoder`: ORG's object graph and its evaluation
protocol; `ImaginationVariant`: where i_tau comes from and what f_w learns), turned into code
in one place, `foresit_jax.networks.build` (the networks) and the functions of
`foresit_jax.rollout` (acting) that read them; nothing outside this module tests a piece's
name (tests/agent/test_methods.py checks it). This module imports nothing of foresit_jax, so that
`Config` (which imports it alone) sits near the ground of the package.
"""

from __future__ import annotations

import dataclasses
from typing import Optional

BASES: tuple[str, ...] = ("a3c", "maml")
ENCODERS: tuple[str, ...] = ("plain", "org")
CRITICS: tuple[str, ...] = ("plain", "attention")
# The pieces that name a critic in a method's name.
CRITIC_PIECES: dict[str, str] = {"critic": "attention", "plaincritic": "plain"}
GRADIENTS: tuple[str, ...] = ("replay", "through_rollout")

ROLLOUTS: tuple[str, ...] = ("packed", "episodes")


@dataclasses.dataclass(frozen=True)
class ImaginationVariant:
    """An imagination variant: where i_tau comes from, when it is renewed, what f_w learns.

    source: 'none' (the policy sees s_t only), 'learned' (f_w([s_0 : g_tau]) + noise,
      Eq. 6-7), 'random' (tanh(z), z ~ N(0, rnd_variance I)), 'goal_view' (privileged: the
      network's encoder and one LSTM step from a fresh carry on the episode's goal view,
      + noise as Eq. 6-7; f_w is not trained), 'cue' (privileged: the observation's
      `cue`, a fact of the environment named by `cue`, zero-padded to H, exact, at every
      step; f_w is not trained).
    cue: for source 'cue', the cue `envs.wrappers.CueWrapper` adds: 'optimal_action',
      'compass' (both renewed every step) or 'compass_at_start' (held for the episode).
    critic: the critic a method with this variant gets unless its name says otherwise
      ('attention' for every variant of the paper, 'plain' for none).
    subgoal_mode: what f_w learns to imagine: 'argmax' (s_{argmax alpha}) or
      'attention_average' (sum_j alpha_j s_j).
    renew_every_k: renew i_tau from s_t every `Config.int_interval` steps of the episode
      (the `int` ablation) instead of once, from s_0, at its start.
    """

    name: str
    source: str = "none"
    critic: str = "plain"
    subgoal_mode: str = "argmax"
    renew_every_k: bool = False
    cue: str = ""
    # Derived from `source` when the record is made (flags, not code run at every step):
    uses_imagination: bool = dataclasses.field(init=False, repr=False)
    """Whether the policy sees an i_tau at all."""
    reads_goal_view: bool = dataclasses.field(init=False, repr=False)
    """Whether i_tau comes from the episode's goal view (privileged: the environment is
    wrapped in `envs.wrappers.GoalViewWrapper`)."""
    trains_imagination: bool = dataclasses.field(init=False, repr=False)
    """Whether buffers are filled and f_w is trained."""
    reads_cue: bool = dataclasses.field(init=False, repr=False)
    """Whether i_tau is a privileged cue of the environment (wrapped in
    `envs.wrappers.CueWrapper`), read from the observation at every step: it exists before
    the step's state does, so the encoder sees it from an episode's first step on."""

    def __post_init__(self):
        object.__setattr__(self, "uses_imagination", self.source != "none")
        object.__setattr__(self, "reads_goal_view", self.source == "goal_view")
        object.__setattr__(self, "trains_imagination", self.source == "learned")
        object.__setattr__(self, "reads_cue", self.source == "cue")
        if self.reads_cue != bool(self.cue):
            raise ValueError(f"imagination {self.name!r}: a cue is named exactly when the source is 'cue'")


_FORESIT = ImaginationVariant("foresit", source="learned", critic="attention")

IMAGINATION_VARIANTS: dict[str, ImaginationVariant] = {
    "none": ImaginationVariant("none"),
    "foresit": _FORESIT,
    "rnd": dataclasses.replace(_FORESIT, name="rnd", source="random"),
    "att": dataclasses.replace(_FORESIT, name="att", subgoal_mode="attention_average"),
    "int": dataclasses.replace(_FORESIT, name="int", renew_every_k=True),
    # Privileged, a diagnostic (docs/ceiling.md): ForeSIT with i_tau from the goal view.
    "oracle": dataclasses.replace(_FORESIT, name="oracle", source="goal_view"),
    # Privileged positive controls (docs/plans/ceiling_channels.md): i_tau is a cue of the
    # environment, exact: the oracle's action, the target's compass per step or at the start.
    "optaction": dataclasses.replace(_FORESIT, name="optaction", source="cue", cue="optimal_action"),
    "compass": dataclasses.replace(_FORESIT, name="compass", source="cue", cue="compass"),
    "startcompass": dataclasses.replace(_FORESIT, name="startcompass", source="cue", cue="compass_at_start"),
}


@dataclasses.dataclass(frozen=True)
class Base:
    """A base learner, as flags (`foresit_jax.networks.build` turns them into code).

    adapts_in_episode: the parameters change inside an episode (maml: SAVN's inner loop,
      `foresit_jax.maml`, with its learned loss L_phi as the network's extra module):
      acting must be differentiated through (the replay re-runs a window under one
      parameter set), in whole episodes (the inner loop counts steps from the start; the
      meta-loss spans the episode), with the previous action probabilities carrying
      gradient (as in SAVN, whose episode is one graph); evaluation holds a parameter copy
      per lane. False (a3c): one parameter set acts a whole window.
    """

    name: str
    adapts_in_episode: bool = False


@dataclasses.dataclass(frozen=True)
class Encoder:
    """An observation encoder piece, as flags: `object_graph`, ORG's object-relation graph
    joins SAVN's encoder (`foresit_jax.org.ObjectGraph`); `greedy_evaluation`: evaluate
    with the argmax action (ORG's own protocol; SAVN and the paper's other rows sample);
    `required_setup`: the setup whose observations it needs (ORG: the detector features
    of `org`)."""

    name: str
    object_graph: bool = False
    greedy_evaluation: bool = False
    required_setup: Optional[str] = None


BASE_PIECES: dict[str, Base] = {
    "a3c": Base("a3c"),
    "maml": Base("maml", adapts_in_episode=True),
}
ENCODER_PIECES: dict[str, Encoder] = {
    "plain": Encoder("plain"),
    "org": Encoder("org", object_graph=True, greedy_evaluation=True, required_setup="org"),
}


@dataclasses.dataclass(frozen=True)
class Method:
    """One method of the paper: base x encoder x critic x imagination (critic None: the
    imagination's default)."""

    base: str = "a3c"
    encoder: str = "plain"
    imagination_variant: ImaginationVariant = IMAGINATION_VARIANTS["none"]
    critic: str | None = None
    # Derived when the record is made (flags, not code run at every step):
    base_piece: Base = dataclasses.field(init=False, repr=False)
    encoder_piece: Encoder = dataclasses.field(init=False, repr=False)
    attention_critic: bool = dataclasses.field(init=False, repr=False)
    """Whether the value comes from the attention of Eq. 3-4 (V(s*_t))."""
    action_probs_carry_gradient: bool = dataclasses.field(init=False, repr=False)
    """Whether the previous step's action probabilities, an input of the encoder, carry
    gradient to the earlier steps. maml: yes, as in SAVN, whose episode is one graph
    (the inner and the meta-gradient both flow through them). a3c: no, they are inputs
    like the observation, which is what lets the replay re-run a window from its
    recorded inputs (the differentiate-through-rollout reference matches it)."""

    def __post_init__(self):
        if self.base not in BASE_PIECES or self.encoder not in ENCODER_PIECES:
            raise ValueError(
                f"base must be one of {BASES} and encoder one of {ENCODERS}, got {self.base!r}, {self.encoder!r}"
            )
        if self.critic is None:
            object.__setattr__(self, "critic", self.imagination_variant.critic)
        if self.critic not in CRITICS:
            raise ValueError(f"critic must be one of {CRITICS}, got {self.critic!r}")
        if self.imagination_variant.subgoal_mode == "attention_average" and self.critic != "attention":
            raise ValueError(
                f"imagination {self.imagination_variant.name!r} imagines the attention-weighted average of the "
                f"episode's states: it needs the attention critic (drop 'plaincritic')"
            )
        base = BASE_PIECES[self.base]
        object.__setattr__(self, "base_piece", base)
        object.__setattr__(self, "encoder_piece", ENCODER_PIECES[self.encoder])
        object.__setattr__(self, "attention_critic", self.critic == "attention")
        object.__setattr__(self, "action_probs_carry_gradient", base.adapts_in_episode)

    @property
    def name(self) -> str:
        parts = ["a3c", "maml"] if self.base == "maml" else [self.base]
        if self.encoder != "plain":
            parts.append(self.encoder)
        if self.imagination_variant.name != "none":
            parts.append(self.imagination_variant.name)
        if self.critic != self.imagination_variant.critic:
            parts.append({v: k for k, v in CRITIC_PIECES.items()}[self.critic])
        return "+".join(parts)

    @property
    def gradients(self) -> tuple[str, ...]:
        """Gradient paths this method supports. The replay re-runs the modules over a
        window's recorded inputs under ONE parameter set: right for a3c, wrong for maml,
        whose steps run under the parameters adapted so far in the episode."""
        return ("through_rollout",) if self.base_piece.adapts_in_episode else GRADIENTS

    @property
    def rollouts(self) -> tuple[str, ...]:
        """Rollout layouts this method supports: maml's inner loop counts steps from each
        episode's start and its meta-loss spans the whole episode, so it needs whole
        episodes (SAVN's layout)."""
        return ("episodes",) if self.base_piece.adapts_in_episode else ROLLOUTS

    @property
    def required_config(self) -> dict:
        """Config fields this method needs (a preset sets them for it): maml acts in
        whole episodes, differentiated through the rollout."""
        return {"rollout": "episodes", "gradient": "through_rollout"} if self.base_piece.adapts_in_episode else {}

    @property
    def privileged(self) -> bool:
        """Whether the method reads what no agent can see (the `oracle` imagination and the
        cues): a diagnostic, labelled privileged wherever it is reported."""
        return self.imagination_variant.reads_goal_view or self.imagination_variant.reads_cue

    @property
    def greedy_evaluation(self) -> bool:
        """Whether evaluation takes the argmax action: ORG's own protocol (its evaluation
        is greedy); SAVN's (and the paper's other rows) sample from the policy."""
        return self.encoder_piece.greedy_evaluation

    @property
    def required_setup(self) -> str | None:
        """The object graph needs the `org` setup's detector features."""
        return self.encoder_piece.required_setup


# The paper's names for its rows, for reference (Table 1 and Table 3).
PAPER_METHODS: tuple[str, ...] = (
    "a3c",
    "a3c+foresit",
    "a3c+maml",
    "a3c+maml+foresit",
    "a3c+org",
    "a3c+org+foresit",
    "a3c+org+rnd",
    "a3c+org+att",
    "a3c+org+int",
)
# The methods that run: the paper's rows and ablations, and the attention critic alone
# (any other combination of the pieces, e.g. 'a3c+maml+org', 'a3c+maml+rnd' or
# 'a3c+foresit+plaincritic', runs too).
IMPLEMENTED_METHODS: tuple[str, ...] = (
    "a3c",
    "a3c+foresit",
    "a3c+rnd",
    "a3c+att",
    "a3c+int",
    "a3c+maml",
    "a3c+maml+foresit",
    "a3c+org",
    "a3c+org+foresit",
    "a3c+org+rnd",
    "a3c+org+att",
    "a3c+org+int",
    "a3c+critic",
    "a3c+org+critic",
    "a3c+oracle",
    "a3c+org+oracle",  # privileged diagnostics, not methods (docs/ceiling.md)
    "a3c+optaction",
    "a3c+compass",
    "a3c+startcompass",  # privileged controls (docs/ceiling.md)
)


def parse_method(name: str) -> Method:
    """`'a3c+org+foresit'` -> Method(base='a3c', encoder='org', imagination_variant=foresit).

    Raises ValueError naming the valid pieces on an unknown or repeated piece."""
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"method must be a non-empty name like 'a3c+foresit', got {name!r}")
    base, encoder, critic, imagination = None, None, None, None
    valid = (
        f"bases {list(BASES)}, encoders {[e for e in ENCODERS if e != 'plain']}, critics {list(CRITIC_PIECES)}, "
        f"imagination {list(IMAGINATION_VARIANTS)}"
    )
    pieces = name.strip().lower().split("+")
    if "a3c" in pieces and "maml" in pieces:  # 'a3c+maml': MAML trains the A3C learner
        pieces.remove("a3c")
    for piece in pieces:
        if piece in BASES:
            slot, value = "base", piece
        elif piece in ENCODERS:
            slot, value = "encoder", piece
        elif piece in CRITIC_PIECES:
            slot, value = "critic", piece
        elif piece in IMAGINATION_VARIANTS:
            slot, value = "imagination", piece
        else:
            raise ValueError(f"unknown piece {piece!r} in method {name!r}; pieces are '+'-joined {valid}")
        current = {"base": base, "encoder": encoder, "critic": critic, "imagination": imagination}[slot]
        if current is not None:
            raise ValueError(f"method {name!r} names two {slot} pieces ({current!r} and {value!r})")
        if slot == "base":
            base = value
        elif slot == "encoder":
            encoder = value
        elif slot == "critic":
            critic = value
        else:
            imagination = value
    try:
        return Method(
            base or "a3c",
            encoder or "plain",
            IMAGINATION_VARIANTS[imagination or "none"],
            CRITIC_PIECES[critic] if critic else None,
        )
    except ValueError as e:
        raise ValueError(f"method {name!r}: {e}") from None
