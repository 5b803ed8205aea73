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
`Config` validates it with the setup. Each piece is a small record of behaviour the agent
calls (`Base`: how a window is acted and the network's extra module; `Encoder`: ORG's
object graph and its evaluation protocol; `ImaginationVariant`: where i_tau comes from and what
f_w learns); nothing outside this module tests a piece's name (tests/test_methods.py
checks it).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, NamedTuple, Optional

import chex
import flax.linen as nn
import jax

from foresit_jax import imagination
from foresit_jax import maml
from foresit_jax.org import ObjectGraph

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
      + noise as Eq. 6-7; f_w is not trained).
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

    @property
    def uses_imagination(self) -> bool:
        return self.source != "none"

    @property
    def reads_goal_view(self) -> bool:
        """Whether i_tau comes from the episode's goal view (privileged: the environment is
        wrapped in `envs.wrappers.GoalViewWrapper`)."""
        return self.source == "goal_view"

    @property
    def trains_imagination(self) -> bool:
        """Whether buffers are filled and f_w is trained."""
        return self.source == "learned"

    def renews(self, episode_step: chex.Array, interval: int) -> chex.Array:
        """Whether i_tau is (re)imagined at this step of the episode, `[...]` bool."""
        if self.renew_every_k:
            return episode_step % interval == 0
        return episode_step == 0

    def imagine(
        self, imagine_fn: Callable, w_params, s_t: chex.Array, goal: chex.Array, key: chex.PRNGKey,
        noise_variance: chex.Array, rnd_variance: float, noise_on_input: bool = False,
        goal_latent: Optional[chex.Array] = None,
    ) -> chex.Array:  # fmt: skip
        """i_tau `[B, H]` for the policy (stop-gradient: the policy loss never trains f_w
        or, through it, s_0). learned: f_w([s_t : g]) + N(0, sigma2) (Eq. 6), or with
        `noise_on_input` f_w([s_t : g] + N(0, sigma2)) (Algorithm 1; Config.imagination_noise);
        random: tanh(N(0, v)); goal_view: `goal_latent` `[B, H]` + N(0, sigma2)."""
        if self.source == "random":
            return imagination.random_imagination(key, s_t.shape, rnd_variance)
        if self.reads_goal_view:
            return jax.lax.stop_gradient(imagination.add_imagination_noise(key, goal_latent, noise_variance))
        if noise_on_input:
            s_in, goal_in = imagination.add_input_noise(key, jax.lax.stop_gradient(s_t), goal, noise_variance)
            return jax.lax.stop_gradient(imagine_fn(w_params, s_in, goal_in))
        imagined = imagine_fn(w_params, jax.lax.stop_gradient(s_t), goal)
        return jax.lax.stop_gradient(imagination.add_imagination_noise(key, imagined, noise_variance))


_FORESIT = ImaginationVariant("foresit", source="learned", critic="attention")

IMAGINATION_VARIANTS: dict[str, ImaginationVariant] = {
    "none": ImaginationVariant("none"),
    "foresit": _FORESIT,
    "rnd": dataclasses.replace(_FORESIT, name="rnd", source="random"),
    "att": dataclasses.replace(_FORESIT, name="att", subgoal_mode="attention_average"),
    "int": dataclasses.replace(_FORESIT, name="int", renew_every_k=True),
    # Privileged, a diagnostic (docs/ceiling.md): ForeSIT with i_tau from the goal view.
    "oracle": dataclasses.replace(_FORESIT, name="oracle", source="goal_view"),
}


class BaseFunctions(NamedTuple):
    """What a base's `act` uses of the agent: pure functions of its networks (`Agent`
    builds them once, `Agent.base_functions`).

    act_window: `(acting, env, actor, key, num_steps, options, *, alive=None,
      lstm_update=None, gate_offsets=None) -> (actor, traj, end)`: a window under one
      parameter set (`Agent.act_window`);
    lstm_inputs: `(params, obs, prev_action_probs, encoder_imagined) -> x_t`, the encoder
      LSTM's input (`Agent.lstm_inputs`);
    interaction_loss: `(params, inputs) -> scalar`, the maml base's L_phi
      (`Agent.interaction_loss`).
    """

    act_window: Callable
    lstm_inputs: Callable
    interaction_loss: Callable


def act_in_windows(fns: BaseFunctions, settings, acting, env, actor, key, num_steps: int, options):
    """The a3c base's acting: one parameter set for the whole window (`act_window`)."""
    return fns.act_window(acting, env, actor, key, num_steps, options)


def act_adapting(fns: BaseFunctions, settings: maml.InnerLoop, acting, env, actor, key, num_steps: int, options):
    """The maml base's acting: SAVN's inner loop adapts each lane's parameters inside its
    episode (`foresit_jax.maml.adaptive_act`, run as `settings` says); whole episodes only."""
    if not options.whole_episodes or options.step_keys is not None:
        raise ValueError("the maml base acts in whole episodes (rollout='episodes'), without step_keys")
    actor, traj, end, _ = maml.adaptive_act(fns, settings, acting, env, actor, key, num_steps, options)
    return actor, traj, end


@dataclasses.dataclass(frozen=True)
class Base:
    """A base learner, as the agent uses it.

    act: acts a window, `(fns: BaseFunctions, settings, acting: AgentParams, env: BoundEnv,
      actor, key, num_steps, options: ActOptions) -> (actor, traj, end)` (the records of
      `foresit_jax.agent`).
    settings: what `act` needs of the Config (maml's `InnerLoop`), from the Config; None
      for none.
    learned_loss: the network's extra module for the base (maml's L_phi), from the Config;
      None for none.
    adapts_in_episode: the parameters change inside an episode (maml): acting must be
      differentiated through (the replay re-runs a window under one parameter set), in
      whole episodes (the inner loop counts steps from the start; the meta-loss spans the
      episode), with the previous action probabilities carrying gradient (as in SAVN,
      whose episode is one graph); evaluation holds a parameter copy per lane.
    """

    name: str
    act: Callable = act_in_windows
    settings: Callable[..., Any] = lambda config: None
    learned_loss: Callable[..., Optional[nn.Module]] = lambda config: None
    adapts_in_episode: bool = False


@dataclasses.dataclass(frozen=True)
class Encoder:
    """An observation encoder piece: `object_graph()` is the module ORG adds to SAVN's
    encoder (None for none); `greedy_evaluation`: evaluate with the argmax action (ORG's
    own protocol; SAVN and the paper's other rows sample); `required_setup`: the setup
    whose observations it needs (ORG: the detector features of `org`)."""

    name: str
    object_graph: Callable[[], Optional[nn.Module]] = lambda: None
    greedy_evaluation: bool = False
    required_setup: Optional[str] = None


BASE_PIECES: dict[str, Base] = {
    "a3c": Base("a3c"),
    "maml": Base("maml", act=act_adapting, settings=maml.InnerLoop.of, adapts_in_episode=True,
                 learned_loss=lambda config: maml.LearnedLoss(segment=config.maml_segment)),  # fmt: skip
}
ENCODER_PIECES: dict[str, Encoder] = {
    "plain": Encoder("plain"),
    "org": Encoder("org", object_graph=ObjectGraph, greedy_evaluation=True, required_setup="org"),
}


@dataclasses.dataclass(frozen=True)
class Method:
    """One method of the paper: base x encoder x critic x imagination (critic None: the
    imagination's default)."""

    base: str = "a3c"
    encoder: str = "plain"
    imagination_variant: ImaginationVariant = IMAGINATION_VARIANTS["none"]
    critic: str | None = None

    def __post_init__(self):
        if self.base not in BASE_PIECES or self.encoder not in ENCODER_PIECES:
            raise ValueError(f"base must be one of {BASES} and encoder one of {ENCODERS}, got {self.base!r}, "
                             f"{self.encoder!r}")  # fmt: skip
        if self.critic is None:
            object.__setattr__(self, "critic", self.imagination_variant.critic)
        if self.critic not in CRITICS:
            raise ValueError(f"critic must be one of {CRITICS}, got {self.critic!r}")
        if self.imagination_variant.subgoal_mode == "attention_average" and self.critic != "attention":
            raise ValueError(
                f"imagination {self.imagination_variant.name!r} imagines the attention-weighted average of the "
                f"episode's states: it needs the attention critic (drop 'plaincritic')"
            )

    @property
    def base_piece(self) -> Base:
        return BASE_PIECES[self.base]

    @property
    def encoder_piece(self) -> Encoder:
        return ENCODER_PIECES[self.encoder]

    @property
    def attention_critic(self) -> bool:
        """Whether the value comes from the attention of Eq. 3-4 (V(s*_t))."""
        return self.critic == "attention"

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
    def action_probs_carry_gradient(self) -> bool:
        """Whether the previous step's action probabilities, an input of the encoder, carry
        gradient to the earlier steps. maml: yes, as in SAVN, whose episode is one graph
        (the inner and the meta-gradient both flow through them). a3c: no, they are inputs
        like the observation, which is what lets the replay re-run a window from its
        recorded inputs (the differentiate-through-rollout reference matches it)."""
        return self.base_piece.adapts_in_episode

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
        """Whether the method reads what no agent can see (the `oracle` imagination): a
        diagnostic, labelled privileged wherever it is reported."""
        return self.imagination_variant.reads_goal_view

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
    "a3c", "a3c+foresit", "a3c+maml", "a3c+maml+foresit", "a3c+org", "a3c+org+foresit",
    "a3c+org+rnd", "a3c+org+att", "a3c+org+int",
)  # fmt: skip
# Methods that run today: the paper's rows and ablations, and the attention critic alone
# (any other combination of the pieces, e.g. 'a3c+maml+org', 'a3c+maml+rnd' or
# 'a3c+foresit+plaincritic', runs too).
IMPLEMENTED_METHODS: tuple[str, ...] = (
    "a3c", "a3c+foresit", "a3c+rnd", "a3c+att", "a3c+int",
    "a3c+maml", "a3c+maml+foresit",
    "a3c+org", "a3c+org+foresit", "a3c+org+rnd", "a3c+org+att", "a3c+org+int",
    "a3c+critic", "a3c+org+critic",
    "a3c+oracle", "a3c+org+oracle",  # privileged diagnostics, not methods (docs/ceiling.md)
)  # fmt: skip


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
            base or "a3c", encoder or "plain", IMAGINATION_VARIANTS[imagination or "none"],
            CRITIC_PIECES[critic] if critic else None,
        )  # fmt: skip
    except ValueError as e:
        raise ValueError(f"method {name!r}: {e}") from None
