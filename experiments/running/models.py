"""Trained models read back from a run folder (`train`, or a sweep's arm) or a sweep folder (`sweep`): one
`Model` per seed, with the training state at its end and the model selected on validation,
for the programs that play or probe them (probe, failures, paper); and `load`, a trained
policy for a user's own code (`experiments.load`, docs/extending.md)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Callable, NamedTuple

import jax
import numpy as np

from experiments import errors
from experiments.running import checkpoint, devices, run, selection, sweeps
from experiments import rundir
from foresit_jax.config import Config
from foresit_jax.evaluate import acting_policy, agent_params
from foresit_jax.train import make_trainer


@dataclasses.dataclass
class Model:
    """One seed's model to probe."""

    config: object
    trainer: object
    seed: int
    state: object  # the training RunnerState, with the selected model's params and w
    selected: object  # AgentParams of the selected model


@dataclasses.dataclass
class Trained:
    """A run folder's models, stacked over its seeds: the training states at its last
    checkpoint and the models selected on validation by then."""

    config: object
    schedule: dict
    seeds: list[int]
    trainer: object
    states: object  # RunnerState, leaves [seeds, ...]
    selected: object  # AgentParams, leaves [seeds, ...]
    selected_updates: list[int]
    update: int  # the updates the states have trained


def read_trained(folder: Path) -> Trained:
    """The models of a run folder (`train`'s, or an arm's in a sweep: `experiments.running.run`),
    or of a train folder of before that format (run.json with one seed, best/)."""
    info = rundir.read_run_info(folder)
    if not run.is_legacy_train_folder(info):
        one = run.read(folder)
        progress = one.progress()
        done = progress["done"]
        if not done:
            raise errors.UserError(f"{folder} has no checkpoint yet (no chunk finished); train it first")
        trainer, states, selected = one.load_checkpoint(done)
        return Trained(
            one.config, info["schedule"], list(one.seeds), trainer, states, selected, progress["best_update"], done
        )
    config = Config(**info["config"])
    trainer = make_trainer(config)

    def shapes(key):  # what the two checkpoints hold, as shapes (`eval_shape`: nothing runs)
        state = trainer.init(key)
        return state, agent_params(state, config.sigma2_max, config.evaluation_noise)

    like, like_selected = jax.eval_shape(shapes, selection.run_key(info["seed"]))
    managers = [checkpoint.checkpoint_manager(folder / name, 100) for name in (rundir.CHECKPOINTS, "best")]
    steps = [m.latest_step() for m in managers]
    if None in steps:
        raise errors.UserError(
            f"{folder} has no finished checkpoint (checkpoints/ and best/); train it to the end first"
        )
    state = checkpoint.restore(managers[0], steps[0], like)
    selected = checkpoint.restore(managers[1], steps[1], like_selected)
    states, selected = jax.tree.map(lambda x: x[None], (state, selected))
    return Trained(config, info["schedule"], [info["seed"]], trainer, states, selected, [steps[1]], steps[0])


def _models(config, trainer, seeds, states, selected) -> list[Model]:
    """One `Model` per seed of states and selected models stacked on a seed axis: each seed's
    state carries its selected model's parameters."""
    models = []
    for i, seed in enumerate(seeds):
        state, chosen = jax.tree.map(lambda x: x[i], (states, selected))
        state = state._replace(params=chosen.params, imagination_params=chosen.imagination_params)
        models.append(Model(config, trainer, seed, state, chosen))
    return models


def models_of_run(folder: Path) -> dict[str, list[Model]]:
    """{method: [Model per seed]} of a run folder (`read_trained`)."""
    trained = read_trained(folder)
    return {
        trained.config.method: _models(trained.config, trained.trainer, trained.seeds, trained.states, trained.selected)
    }


def models_of_sweep(folder: Path, methods: tuple[str, ...]) -> dict[str, list[Model]]:
    """{method: [Model per seed]} of a sweep's finished methods."""
    args = sweeps.saved(folder)
    finished = [m for m in args.methods if rundir.finished_seeds(rundir.arm_folder(folder, m))]
    unknown = [m for m in methods if m not in finished]
    if unknown:
        raise errors.UserError(
            f"{folder} has no finished {', '.join(unknown)}; finished: {', '.join(finished) or 'none'}"
        )
    out = {}
    for method in methods or finished:
        config, _ = sweeps.method_schedule(method, args)
        if not methods and not (config.pieces.imagination_variant.uses_imagination or config.pieces.attention_critic):
            continue
        config, trainer, states, best = sweeps.load_method(method, args, rundir.arm_folder(folder, method))
        out[method] = _models(config, trainer, rundir.finished_seeds(rundir.arm_folder(folder, method)), states, best)
    return out


class Policy(NamedTuple):
    """A trained policy (`load`): `act(params, carry, obs, first, key) -> (action [B], carry)`
    is pure and batched over lanes (`foresit_jax.policy.policy`, or `foresit_jax.maml.policy`: `first` `[B]` marks an
    episode's first step, where the carry resets; with the maml base the carry holds each
    lane's adapted parameters, and `key` is one per lane, `[B, 2]`: `act.step_keys` gives
    the keys a rollout uses); `params` what it acts with (theta/omega, f_w's w, the
    evaluation's noise variance); `initial_carry(num_lanes)` its carry before a first step;
    `config` the run's Config. `test_key` and `test_episodes_per_room` give
    the episodes the run's report tested it on (`foresit_jax.evaluate.evaluate_policy`)."""

    act: Callable
    params: Any
    initial_carry: Callable[[int], Any]
    config: Config
    test_key: jax.Array
    test_episodes_per_room: int


WHICH = ("best", "last")


def load(run_dir, seed: int = 0, which: str = "best") -> Policy:
    """The policy a run folder (`python -m experiments.train`'s, or a sweep's arm,
    `<sweep>/methods/<arm>`) trained for `seed`: `which` is "best", the model selected on
    validation (what results.json reports as "selected"), or "last", the state at the run's
    last checkpoint. Acts as the run's evaluation does (its greedy or sampled protocol, the
    evaluation noise): `evaluate_policy(p.act, p.params, p.initial_carry, p.config, "test",
    p.test_key, p.test_episodes_per_room)` gives results.json's test numbers. A `seed` that is
    not an int (0.0, True) is refused in one line before anything is read; one the run did
    not train, or parameters whose shapes are not those of the run's Config, before acting."""
    if which not in WHICH:
        raise errors.UserError(f"which must be one of {WHICH}, got {which!r}")
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):  # 0.0 == 0 would pass below
        raise errors.UserError(
            f"load: seed must be an int (one of the run's seeds), got {seed!r} ({type(seed).__name__})"
        )
    seed = int(seed)
    folder = Path(run_dir)
    sweep = rundir.is_sweep(folder)
    rundir.require_run(folder, " (a sweep folder: give one of its arms, <sweep>/methods/<arm>)" if sweep else "")
    trained = read_trained(folder)
    if seed not in trained.seeds:
        raise errors.UserError(f"{folder} trained seeds {trained.seeds}, not seed {seed}")
    i, config = trained.seeds.index(seed), trained.config
    if which == "best":
        params = devices.seed_slice(trained.selected, i)
    else:  # as the run's report computes the last model's (`Run.test`)
        params = devices.seed_slice(run.seeds_params(config, trained.states), i)
    try:  # the parameters' tree and shapes against the run's Config (a run.json edited by hand)
        act, params, carry, _ = acting_policy(config, params, "load")
    except ValueError as e:
        raise errors.UserError(f"{folder}: {e}") from None
    return Policy(act, params, carry, config, selection.test_key(seed), trained.schedule["test_episodes_per_room"])
