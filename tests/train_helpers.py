"""Shared, process-wide cached builders for the agent/training/experiment tests.

Compiling one training update takes 10-20 s on a 2-core CPU even at tiny sizes, so the
tests share compiled functions: every builder here is `functools.lru_cache`d (one
Trainer and one jitted function per config for the whole pytest session, across test
modules).  Test programs are compiled with XLA's backend optimisation level 0
(`FAST_COMPILE`): about 3x faster to compile, slower to run, which is the right trade for
a handful of tiny updates.  Bitwise comparisons are only ever made between programs
compiled with the same options.
"""

from __future__ import annotations

import functools
import importlib
import pkgutil

import chex
import jax
import jax.numpy as jnp
import numpy as np

import envs
from foresit_jax.config import Config
from foresit_jax.methods import parse_method
from foresit_jax.train import Trainer

FAST_COMPILE = {"xla_backend_optimization_level": 0}

# The smallest sensible agent: bathrooms only (the smallest scene bank and the shortest
# paths), 4 lanes, 16 hidden units.  num_steps stays 30 (the training time limit).
TINY = dict(
    room_types=("bathroom",),
    num_lanes=4,
    num_updates=2,
    hidden_size=16,
    attention_size=16,
    value_hidden=16,
    imagination_layer_sizes=(16, 8, 4, 8, 16, 16),
    buffer_size=1,
    imagination_epochs=1,
    learning_rate=1e-3,
)

METHODS = ("a3c", "a3c+foresit", "rnd", "att", "int", "a3c+critic", "a3c+foresit+plaincritic")
ORG_METHODS = ("a3c+org", "a3c+org+foresit", "a3c+org+rnd", "a3c+org+att", "a3c+org+int")


def tiny_config(method: str = "a3c+foresit", **overrides) -> Config:
    return Config(method=method, **{**TINY, **parse_method(method).required_config, **overrides})


@functools.lru_cache(maxsize=None)
def bathroom_env(split: str = "train", training: bool | None = None):
    """(env, params) of the savn bathrooms (the bank is shared with `make_env` of a
    bathroom-only config through envs' own cache)."""
    return envs.make("GridNav-v0", setup="savn", split=split, room_types=("bathroom",), training=training)


@functools.lru_cache(maxsize=None)
def org_bathroom_env(split: str = "train", training: bool | None = None):
    """(env, params) of the org setup's bathrooms (detector features in the observation)."""
    return envs.make("GridNav-v0", setup="org", split=split, room_types=("bathroom",), training=training)


@functools.lru_cache(maxsize=None)
def trainer(config: Config) -> Trainer:
    env, env_params = org_bathroom_env() if config.setup == "org" else bathroom_env()
    return Trainer(config, env, env_params)


@functools.lru_cache(maxsize=None)
def jitted_init(config: Config):
    return jax.jit(trainer(config).init, compiler_options=FAST_COMPILE)


@functools.lru_cache(maxsize=None)
def jitted_update(config: Config):
    """`jit(update)`; wrapped in `chex.assert_max_traces(n=1)`, so every test that
    calls it also checks that chained updates never re-trace."""
    update = trainer(config).update

    def update_of_config(state, env_params):
        return update(state, env_params)

    # chex counts traces per (call stack, source, name): give each config its own name.
    update_of_config.__name__ = f"update_{config.method}_{abs(hash(config))}"
    return jax.jit(chex.assert_max_traces(update_of_config, n=1), compiler_options=FAST_COMPILE)


def run_updates(config: Config, state, num_updates: int):
    """`num_updates` calls of the shared jitted update; metrics stacked `[n]` (numpy)."""
    update, env_params = jitted_update(config), trainer(config).env_params
    history = []
    for _ in range(num_updates):
        state, metrics = update(state, env_params)
        history.append(metrics)
    return state, jax.tree.map(lambda *m: np.stack([np.asarray(x) for x in m]), *history)


def init_and_run(config: Config, seed: int, num_updates: int):
    return run_updates(config, jitted_init(config)(jax.random.PRNGKey(seed)), num_updates)


def easy_setting_run(config: Config, env, env_params, num_updates: int = 150):
    """Train `config` from seed 0 on the easy version of `env_params` (`easy_env_params`):
    (initial state, final state, mean training success of the first and of the last 20
    updates)."""
    trainer = Trainer(config, env, easy_env_params(env_params))
    state = jax.jit(trainer.init)(jax.random.PRNGKey(0))
    final, metrics = jax.jit(trainer.run, static_argnums=2)(state, trainer.env_params, num_updates)
    success = np.asarray(metrics["charts/success_rate"])
    return state, final, success[:20].mean(), success[-20:].mean()


def easy_env_params(env_params, max_optimal_length: int = 3):
    """An easy setting: one bathroom, one target, starts within `max_optimal_length`
    actions of success (Done included)."""
    b = env_params.bank
    per_scene = (
        "numbers",
        "room_type",
        "cell_type",
        "obj_cat",
        "obj_band",
        "targets",
        "num_targets",
        "view_sem",
        "view_depth",
        "distance",
        "starts",
        "num_starts",
    )
    b = b.replace(**{f: getattr(b, f)[:1] for f in per_scene})
    starts = np.asarray(b.starts[0, 0]).astype(np.int64)[: int(b.num_starts[0, 0])]
    near = starts[np.asarray(b.distance[0, 0])[starts * 2] <= max_optimal_length]  # pose index = start * 2 (level)
    assert len(near) > 10
    new_starts = np.zeros_like(np.asarray(b.starts))
    new_starts[0, 0, : len(near)] = near
    b = b.replace(
        starts=jnp.asarray(new_starts),
        num_starts=b.num_starts.at[0, 0].set(len(near)),
        num_targets=jnp.ones_like(b.num_targets),
    )
    return env_params.replace(bank=b)


# ------------------------------------------------------------------ tree comparisons
def assert_trees_bitwise_equal(a, b) -> None:
    chex.assert_trees_all_equal_structs(a, b)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def trees_bitwise_equal(a, b) -> bool:
    return all(np.array_equal(np.asarray(x), np.asarray(y)) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)))


def assert_tree_finite(tree) -> None:
    for path, leaf in jax.tree_util.tree_leaves_with_path(tree):
        leaf = np.asarray(leaf)
        if np.issubdtype(leaf.dtype, np.floating):
            assert np.isfinite(leaf).all(), f"non-finite values in {jax.tree_util.keystr(path)}"


def corrupt_checkpoint(folder, how: str = "flipped") -> None:
    """Damage a checkpoint (its biggest file) as a bad disk (16 bytes flipped) or a killed
    copy (truncated to half) would."""
    from experiments.running import checkpoint

    data = sorted(
        (p for p in folder.rglob("*") if p.is_file() and p.name != checkpoint.CHECKSUM_FILE),
        key=lambda p: p.stat().st_size,
    )[-1]
    raw = bytearray(data.read_bytes())
    if how == "flipped":
        rng = np.random.default_rng(0)
        at = rng.integers(0, len(raw) - 16)
        raw[at : at + 16] = rng.integers(0, 256, 16, dtype=np.uint8).tobytes()
    else:
        raw = raw[: len(raw) // 2]
    data.write_bytes(bytes(raw))


def subtree(params, *names):
    """params['params'][names[0]][names[1]]..."""
    node = params["params"]
    for name in names:
        node = node[name]
    return node


def max_abs(tree) -> float:
    leaves = [jnp.max(jnp.abs(x)) for x in jax.tree.leaves(tree)]
    return float(max(leaves)) if leaves else 0.0


# ------------------------------------------------------------------ experiments in-process
@functools.lru_cache(maxsize=None)
def cached_trainer(config: Config, **kwargs) -> Trainer:
    return Trainer(config, **kwargs)


def _make_trainer_cached(config, env=None, env_params=None, **kwargs):
    if env is not None or env_params is not None:
        return Trainer(config, env, env_params, **kwargs)
    return cached_trainer(config, **kwargs)


_REAL_EVALUATOR = importlib.import_module("foresit_jax.evaluate").Evaluator  # before any patching


def _fast_jit(real_jit):
    def jit(fun=None, /, **kwargs):
        kwargs.setdefault("compiler_options", FAST_COMPILE)
        if fun is None:
            return functools.partial(jit, **kwargs)
        return real_jit(fun, **kwargs)

    return jit


def patch_for_experiments(mp) -> None:
    """Make in-process calls of the experiments CLIs cheap, without changing what they do:
    the `tiny` preset trains on bathrooms only (one scene bank, 2 evaluation programs
    instead of 8), `make_trainer` returns one Trainer per config (so every `main()` call
    reuses the same jitted chunk instead of recompiling it: a Trainer is pure), one Evaluator
    per setup (its compiled evaluation rollouts are shared the same way), and jit compiles
    with FAST_COMPILE.

    The programs import `make_trainer` and `Evaluator` at their top (tests/structure/test_layering.py),
    so each module of experiments that holds one is patched too; every such module is
    imported first, so that none imports a patched one while the patch holds and keeps it."""
    import experiments
    import experiments.running.presets as presets
    import foresit_jax.train as train

    evaluate = importlib.import_module("foresit_jax.evaluate")  # the module (the package exports a function)
    programs = [importlib.import_module(m.name) for m in pkgutil.walk_packages(experiments.__path__, "experiments.")]

    fields, schedule = presets.PRESETS["tiny"]
    mp.setitem(presets.PRESETS, "tiny", ({**fields, "room_types": ("bathroom",)}, schedule))
    real_make_trainer = train.make_trainer
    mp.setattr(train, "make_trainer", _make_trainer_cached)
    evaluators = {}  # dropped with the patch (and its compiled rollouts with it)

    class CachedEvaluator(_REAL_EVALUATOR):
        """Evaluator(...) and Evaluator.for_config(...) give the one Evaluator of their scenes."""

        def __new__(
            cls, setup: str = "savn", layout: str = "room", priors: bool = False, perception_range: float | None = None
        ):
            key = (setup, layout, bool(priors), perception_range)
            if key not in evaluators:  # a real Evaluator: its __init__ runs once, here
                evaluators[key] = _REAL_EVALUATOR(*key)
            return evaluators[key]

    mp.setattr(evaluate, "Evaluator", CachedEvaluator)
    for module in programs:
        for name, real, cached in (
            ("make_trainer", real_make_trainer, _make_trainer_cached),
            ("Evaluator", _REAL_EVALUATOR, CachedEvaluator),
        ):
            if getattr(module, name, None) is real:
                mp.setattr(module, name, cached)
    mp.setattr(jax, "jit", _fast_jit(jax.jit))
