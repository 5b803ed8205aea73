"""Named presets: a Config plus the run's schedule (chunks, evaluation sizes).

`quick` is the README's main command: a visible result in minutes on a 2-core CPU, on all
four room types: 32 lanes stepping packed windows of 16 steps, Adam 1e-3, a 128-unit
network (chosen by `benchmarks.search_learner`; docs/learner.md, and the README's figures).
`house` is quick's learner in houses (`layout="house"`) for 12,000 updates, with the
reward shaped by the oracle's distance (`Config.progress_reward` 0.1, a deviation from the
paper's reward: without it a3c learns to give up at the start; docs/houses.md measures it).
`paper` is the paper's sizes and schedule (512-unit LSTM, Adam 1e-4), for long runs on
accelerators.  `tiny` is for tests and smoke runs (bathrooms only, tiny networks).
A method's own requirements (`Method.required_config`: the maml base runs whole
episodes, differentiated through the rollout) are applied over the preset's fields only:
an arm's field (`METHOD@field=value`) or a flag that breaks one is refused, with what the
method needs; one that meets it is kept. A field an arm sets and a flag gives otherwise is
refused too, naming both: a run is what its label (the arm, as the user wrote it) says.
Arms are compared by `normalise_arm` (method case, `1e-3` and `0.001`, spaces, a trailing
comma), never renamed by it.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from typing import Annotated, Optional

import docstring_parser
import numpy as np
import tyro

from envs.gridnav import GridNav, check_room_types, time_limits
from experiments.running import devices
from foresit_jax.config import Config
from foresit_jax.methods import IMPLEMENTED_METHODS, parse_method


@dataclasses.dataclass(frozen=True)
class Schedule:
    """How a run is cut into chunks and evaluated."""

    chunk_updates: int
    """Updates per jitted chunk; between chunks the host logs, checkpoints, validates."""
    val_episodes_per_room: int
    """Validation episodes per room type after each chunk (model selection)."""
    test_episodes_per_room: int
    """Test episodes per room type for the final report (the paper uses 250)."""
    keep_checkpoints: int = 2
    """Most recent checkpoints kept on disk."""


_SMALL_NET = dict(
    hidden_size=128, attention_size=128, value_hidden=128, imagination_layer_sizes=(128, 64, 32, 64, 128, 128)
)

PRESETS: dict[str, tuple[dict, Schedule]] = {
    "tiny": (
        dict(
            num_lanes=4,
            num_updates=4,
            room_types=("bathroom",),
            hidden_size=32,
            attention_size=32,
            value_hidden=32,
            imagination_layer_sizes=(32, 16, 8, 16, 32, 32),
            buffer_size=2,
            imagination_epochs=1,
        ),
        Schedule(chunk_updates=2, val_episodes_per_room=2, test_episodes_per_room=2),
    ),
    "quick": (
        dict(num_lanes=32, num_steps=16, num_updates=3000, learning_rate=1e-3, **_SMALL_NET),
        # 100 validation episodes per room type: SR's standard error ~2.3 points (25 gave ~4.6,
        # more than the selected and last models' test SRs differed by); ~2 s a validation
        # here, ~5% of a 500-update chunk.
        Schedule(chunk_updates=500, val_episodes_per_room=100, test_episodes_per_room=250),
    ),
    "house": (  # quick's learner in houses (envs.houses), for longer, the reward shaped
        dict(
            layout="house",
            num_lanes=32,
            num_steps=16,
            num_updates=12000,
            learning_rate=1e-3,
            progress_reward=0.1,
            **_SMALL_NET,
        ),
        Schedule(chunk_updates=1000, val_episodes_per_room=100, test_episodes_per_room=250),
    ),
    "paper": (
        dict(num_lanes=64, num_updates=50_000),
        Schedule(chunk_updates=500, val_episodes_per_room=250, test_episodes_per_room=250, keep_checkpoints=3),
    ),
}


def check_method(method: str) -> None:
    """A one-line error for a method name that does not parse."""
    try:
        parse_method(method)
    except ValueError as e:
        raise ValueError(f"unknown method {method!r} ({e}); valid methods: {', '.join(IMPLEMENTED_METHODS)}") from None


def split_arm(arm: str) -> tuple[str, dict]:
    """An arm of a comparison: a method with Config fields of its own, written
    `METHOD@field=value,...`, e.g. `a3c+foresit@imagination_input=encoder` or
    `a3c@learning_rate=3e-4,imagination_input=mlp` -> (method, {field: value}); a plain
    method name gives no fields. Values are read as the field's type (str, int, float,
    bool: true/false); a one-line ValueError names what is wrong. (No brackets: the name
    is also a folder name, and orbax's storage cannot read a path with brackets.)"""
    method, at, body = arm.strip().partition("@")
    if at and not body.strip():
        raise ValueError(f"arm {arm!r}: write fields as METHOD@field=value,...")
    defaults = {f.name: f.default for f in dataclasses.fields(Config)}
    fields = {}
    for item in filter(None, (x.strip() for x in body.split(","))):
        field, eq, text = (x.strip() for x in item.partition("="))
        if not eq or not text:
            raise ValueError(f"arm {arm!r}: {item!r} is not field=value")
        if field not in defaults or field in ("method", "setup", "layout", "priors", "perception_range"):
            raise ValueError(
                f"arm {arm!r}: {field!r} is not a Config field an arm can set (the scenes are "
                "the sweep's: --setup, --layout, --priors, --perception-range)"
            )
        kind = type(defaults[field])
        try:
            if kind is bool:
                if text.lower() not in ("true", "false"):
                    raise ValueError
                value = text.lower() == "true"
            elif kind in (int, float, str):
                value = kind(text)
            else:
                raise ValueError
        except ValueError:
            raise ValueError(f"arm {arm!r}: {field}={text!r} is not a {kind.__name__}") from None
        if field in fields and fields[field] != value:
            raise ValueError(f"arm {arm!r} sets {field} twice ({fields[field]!r} and {value!r}); give it once")
        fields[field] = value
    return method.strip(), fields


def _text(value) -> str:
    """A value of an arm's field as `split_arm` reads it back: bools as true/false."""
    return str(value).lower() if isinstance(value, bool) else format(value)


def normalise_arm(arm: str) -> str:
    """The canonical spelling of an arm, to compare two arms (never to name a run: a run
    keeps the user's spelling as its label and folder name): the method as `parse_method`
    names it (lower case, its pieces in order, `a3c+maml` for `maml`), the fields sorted,
    each value as `split_arm` reads it (`1e-3` and `0.001` are both `0.001`), no spaces
    and no trailing comma. `a3c@learning_rate=1e-3,` and `A3C@ learning_rate=0.001` are
    both `a3c@learning_rate=0.001`. A one-line ValueError names an arm that does not parse
    (a field set twice to different values included)."""
    method, fields = split_arm(arm)
    check_method(method)
    name = parse_method(method).name
    return name + ("@" + ",".join(f"{k}={_text(fields[k])}" for k in sorted(fields)) if fields else "")


def duplicate_arms(arms) -> list[tuple[str, str]]:
    """The pairs (first, later) of `arms` that normalise the same (`normalise_arm`): the
    same arm twice, however it is spelt."""
    seen, pairs = {}, []
    for arm in arms:
        key = normalise_arm(arm)
        if key in seen:
            pairs.append((seen[key], arm))
        else:
            seen[key] = arm
    return pairs


def _flag(field: str) -> str:
    return "--" + field.replace("_", "-")


def _required_hint(method: str, field: str, need) -> str:
    """Why `method` needs `field` = `need` (`Method.required_config`), as a refusal says it."""
    if field == "rollout":
        return f"{method} needs whole episodes (rollout={need!r}: its inner loop adapts within each episode)"
    if field == "gradient":
        return (
            f"{method} differentiates through the rollout (gradient={need!r}: a replay cannot re-run the steps "
            "its inner loop adapted)"
        )
    return f"{method} needs {field}={need!r}"


def preset(name: str, method: str, **overrides) -> tuple[Config, Schedule]:
    """The Config and Schedule of a preset for a method (or an arm, `split_arm`: its
    fields override the preset's), with field overrides (None values are ignored).

    Refused in one line (ValueError), before a program writes anything: a field the arm
    sets and an override gives with another value (a run is what its label says); an arm
    field or override that breaks the method's requirements (`Method.required_config`,
    which apply over the preset's fields only); with whole-episode rollouts
    (rollout='episodes', maml's), num_steps below the environment's training time limit
    (the preset's own num_steps is raised to the limit for maml)."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; valid presets: {', '.join(PRESETS)}")
    arm = method
    method, arm_fields = split_arm(arm)
    check_method(method)
    preset_fields, schedule = PRESETS[name]
    given = {k: v for k, v in overrides.items() if v is not None}
    unknown = set(given) - {f.name for f in dataclasses.fields(Config)}
    if unknown:
        raise ValueError(f"unknown config fields {sorted(unknown)}")
    for field, value in arm_fields.items():
        if field in given and given[field] != value:
            raise ValueError(f"arm {arm!r} sets {field}={value!r} but {_flag(field)} gives {given[field]!r}; drop one")
    chosen = {**arm_fields, **given}  # what the user set: kept, or refused
    source = {
        **{k: f"arm {arm!r} sets {k}={v!r}" for k, v in arm_fields.items()},
        **{k: f"{_flag(k)} {v!r}" for k, v in given.items() if k not in arm_fields},
    }
    pieces = parse_method(method)
    required = pieces.required_config
    for field, need in required.items():
        if field in chosen and chosen[field] != need:
            raise ValueError(f"{source[field]}, but {_required_hint(pieces.name, field, need)}; drop it")
    fields = {**preset_fields, **required, **chosen}
    if fields.get("rollout", Config.rollout) == "episodes":  # whole training episodes per update
        limit = int(max(time_limits(True, fields.get("layout", Config.layout))))
        steps = fields.get("num_steps", Config.num_steps)
        maml = required.get("rollout") == "episodes"
        runs = f"runs whole episodes, of up to {limit} steps in training here"
        if steps < limit and "num_steps" in chosen:
            raise ValueError(
                f"{source['num_steps']}, but {pieces.name if maml else 'rollout=episodes'} {runs}: give num_steps "
                f">= {limit}" + (" (or leave it to the preset)" if maml else ", or use rollout='packed'")
            )
        if steps < limit and not maml:
            raise ValueError(
                f"{source.get('rollout', f'preset {name!r} sets rollout=episodes')}, which {runs}, but preset "
                f"{name!r} steps {steps} at a time: give num_steps >= {limit} too, or use rollout='packed'"
            )
        if steps < limit:
            fields["num_steps"] = limit  # the preset's window, raised to whole episodes for the method
    config = Config(method=method, **fields)
    if config.room_types:  # checked here, before a program writes anything in its --out
        check_room_types(config.room_types)
    return config, schedule


MAX_SEED = 2**63 - 1  # jax.random.PRNGKey takes a seed that fits in int64


def check_seeds(first: int, count: int = 1) -> None:
    """A ValueError naming the bound where seeds `first` .. `first + count - 1` do not all
    lie in 0..MAX_SEED (before anything is written)."""
    if isinstance(first, bool) or not isinstance(first, int) or first < 0 or first + count - 1 > MAX_SEED:
        last = f" to {first + count - 1}" if count > 1 else ""
        raise ValueError(
            f"seeds must lie in 0..2**63-1 (what jax.random.PRNGKey takes), got {first}{last}; choose a smaller --seed"
        )


# The bounds past which a run is refused unless --allow-large is given (`check_sizes`): a
# number this large is far more often a typo (an extra 0, a 2**) than a plan.
MAX_UPDATES = 10**7  # quick trains 3000; the paper's preset 50,000
MAX_SEEDS = 4096  # the seeds of one arm, vmapped in one program
MAX_EPISODES = 10**5  # evaluation episodes per room type (the paper tests 250)
MAX_INT32 = 2**31 - 1  # what any count must fit in, --allow-large or not


def observation_bytes(config: Config) -> int:
    """The bytes of one lane's observation at one step (every part of the environment's
    observation space; a wrapper's additions, such as the goal view, are not counted)."""
    env = GridNav(
        setup=config.setup, layout=config.layout, priors=config.priors, perception_range=config.perception_range
    )
    boxes = env.observation_space().spaces.values()
    return sum(int(math.prod(b.shape)) * np.dtype(b.dtype).itemsize for b in boxes)


def window_bytes(config: Config, seeds: int = 1) -> int:
    """A lower bound on what training holds at once: one window's observations, lanes x
    (steps + 1) x observation bytes, for every seed."""
    return seeds * config.num_lanes * (config.num_steps + 1) * observation_bytes(config)


def check_sizes(
    config: Config,
    seeds: int = 1,
    schedule: Schedule | None = None,
    allow_large: bool = False,
    memory: int | None = None,
) -> None:
    """A ValueError naming the bound, before anything is written or compiled, where a run
    asks for more than MAX_UPDATES updates, more than MAX_SEEDS seeds, more than
    MAX_EPISODES evaluation episodes per room type, a count past int32, or a training
    window whose observations alone (`window_bytes`) exceed `memory` (by default the
    machine's: `devices.memory_bytes`). `allow_large` (--allow-large) lifts every bound but int32's."""
    counts = {
        f.name: getattr(config, f.name) for f in dataclasses.fields(config) if type(getattr(config, f.name)) is int
    }
    if schedule is not None:
        counts.update((k, v) for k, v in dataclasses.asdict(schedule).items() if type(v) is int)
    for name, value in counts.items():
        if value > MAX_INT32:
            raise ValueError(
                f"--{name.replace('_', '-')} {value} is past 2**31-1, the largest count XLA's int32 holds; "
                "give a smaller one"
            )
    if allow_large:
        return
    for name in ("test_episodes_per_room", "val_episodes_per_room"):
        if counts.get(name, 0) > MAX_EPISODES:
            raise ValueError(
                f"--{name.replace('_', '-')} {counts[name]} is past the bound of {MAX_EPISODES:,} episodes "
                "per room type; give fewer, or pass --allow-large"
            )
    if config.num_updates > MAX_UPDATES:
        raise ValueError(
            f"--num-updates {config.num_updates} is past the bound of {MAX_UPDATES:,} updates; "
            "give fewer, or pass --allow-large to run it anyway"
        )
    if seeds > MAX_SEEDS:
        raise ValueError(
            f"--seeds {seeds} is past the bound of {MAX_SEEDS} seeds in one program; give fewer (run "
            "more seeds as several sweeps with --seed, combined by --reuse), or pass --allow-large"
        )
    need, have = window_bytes(config, seeds), devices.memory_bytes() if memory is None else memory
    if need > have:
        raise ValueError(
            f"{seeds} seed(s) x {config.num_lanes} lanes x {config.num_steps + 1} steps of "
            f"{observation_bytes(config)}-byte observations need at least {need / 2**30:,.1f} GiB, "
            f"more than this machine's {have / 2**30:,.1f} GiB; lower --num-lanes or --seeds, or pass "
            "--allow-large to try anyway"
        )


# ---------------------------------------------------------------------- Config fields as flags
def _field_docs(cls) -> dict[str, str]:
    """The docstrings written under a dataclass's fields, each on one line: what tyro reads
    (`docstring_parser`, its dependency), with the source's line breaks joined. tyro keeps
    those breaks itself (1.0.17: a line of a field docstring starting with a space starts a
    new help line), so the help it would print for Config's fields is ragged."""
    return {
        p.arg_name: " ".join(p.description.split())
        for p in docstring_parser.parse_from_object(cls).params
        if p.description
    }


def config_fields(name: str, exclude: tuple[str, ...]) -> type:
    """A frozen dataclass of every Config field but `exclude` (a CLI's own flags), each
    optional and None by default: as a CLI's nested, unprefixed argument (`--gamma 0.9`,
    `--room-types bathroom kitchen`) it overrides the preset's value of what it sets,
    with Config's own documentation as its help."""
    docs, hints = _field_docs(Config), typing.get_type_hints(Config)
    fields = [
        (
            f.name,
            Annotated[
                Optional[hints[f.name]],
                tyro.conf.arg(help=docs.get(f.name, ""), help_behavior_hint="(default: the preset's; see --preset)"),
            ],
            dataclasses.field(default=None),
        )
        for f in dataclasses.fields(Config)
        if f.name not in exclude
    ]
    return dataclasses.make_dataclass(name, fields, frozen=True)


# Fields no CLI sets: the method and setup are flags of their own, the action count is the
# environment's.
_NOT_FLAGS = ("method", "setup", "num_actions")


def config_flag(fields_type: type):
    """The annotation of a CLI's field holding `fields_type` (`config_fields`): unprefixed."""
    return Annotated[
        fields_type,
        tyro.conf.OmitArgPrefixes,
        tyro.conf.arg(help="Config fields: each overrides the preset's value (default: the preset's)"),
    ]


def given(fields) -> dict:
    """The fields a user set in a `config_fields` instance (not None)."""
    return {k: v for k, v in dataclasses.asdict(fields).items() if v is not None}


# num_updates is a run flag (`flags.NumUpdates`: with --resume it extends a run), not one of these.
TrainConfigFields = config_fields("TrainConfigFields", (*_NOT_FLAGS, "num_updates"))
SweepConfigFields = config_fields("SweepConfigFields", (*_NOT_FLAGS, "num_updates"))


# ---------------------------------------------------------------------- the programs' named flags
def preset_values(name: str) -> str:
    """What preset `name` sets, as --help shows it: its Config fields and its schedule."""
    fields, schedule = PRESETS[name]
    values = ", ".join(f"{k}={v}" for k, v in fields.items())
    return (
        f"{values}; chunks of {schedule.chunk_updates} updates, {schedule.val_episodes_per_room} validation and "
        f"{schedule.test_episodes_per_room} test episodes per room type"
    )


_PRESET_USES = {
    "tiny": "a smoke check in seconds: it says whether a run works, not what it learns",
    "quick": "a result in minutes on a laptop CPU",
    "house": "quick's learner in houses",
    "paper": "the paper's sizes, for accelerators",
}
_DEFAULTS = Config()

# --preset: its choices and each one's values in --help (tyro: a str shown as the choices, so that
# a name not among them is refused in one line by `preset`, not by tyro's usage box).
PresetFlag = Annotated[
    str,
    tyro.conf.arg(
        metavar="{" + ",".join(PRESETS) + "}",
        help="Preset, a Config and a schedule: "
        + " | ".join(f"{name} ({_PRESET_USES.get(name, '')}): {preset_values(name)}" for name in PRESETS)
        + f" | any field not named is Config's default (e.g. hidden_size={_DEFAULTS.hidden_size}, "
        f"learning_rate={_DEFAULTS.learning_rate}, num_steps={_DEFAULTS.num_steps}); a flag overrides a value.",
    ),
]
# --setup: the environment's two setups.
SetupFlag = Annotated[
    str,
    tyro.conf.arg(
        metavar="{savn,org}",
        help="Environment setup: savn (the first setup: 18 categories, word-vector targets) or org (the second: "
        "22 categories, detector features; the object-graph methods need it).",
    ),
]
_METHODS_HELP = (
    "'+'-joined pieces, one of: " + ", ".join(IMPLEMENTED_METHODS) + "; or an arm, a method with Config fields of "
    "its own, METHOD@field=value,... (e.g. a3c+foresit@imagination_input=encoder)"
)
# --method (train): one method or arm; the choices are in the help, not the type, so that an arm is accepted.
MethodFlag = Annotated[str, tyro.conf.arg(metavar="METHOD[@FIELD=VALUE,...]", help=f"Method: {_METHODS_HELP}.")]
# --methods (sweep, tune): several, the first the base.
MethodsFlag = Annotated[
    tuple[str, ...],
    tyro.conf.arg(
        metavar="METHOD[@FIELD=VALUE,...] ...",
        help=f"Methods (or arms) to compare, the first the base: each {_METHODS_HELP}.",
    ),
]


def smoke_note(name: str, schedule: Schedule, config: Config) -> str | None:
    """What a run of preset `name` is, for its report to say, when it is a smoke check
    (`tiny`: its few updates and episodes tell whether a run works, not what it learns);
    None for the presets that give a result."""
    if name != "tiny":
        return None
    return (
        f"this is a smoke check (preset tiny: {config.num_updates} updates, {schedule.test_episodes_per_room} test "
        "episodes per room type): it shows that training runs, not what the agent learns; for a result run "
        "--preset quick (minutes on a laptop CPU)"
    )
