"""Trained models read back from a run folder (`train`) or a sweep folder (`sweep`): one
`Model` per seed, with the training state at its end and the model selected on validation,
for the programs that play or probe them (probe, failures, paper)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax

from experiments.running import checkpoint, errors, rundir, selection, sweeps


@dataclasses.dataclass
class Model:
    """One seed's model to probe."""

    config: object
    trainer: object
    seed: int
    state: object  # the training RunnerState, with the selected model's params and w
    selected: object  # AgentParams of the selected model


def models_of_run(run: Path) -> dict[str, list[Model]]:
    """{method: [Model]} of a train run folder."""
    from foresit_jax.config import Config
    from foresit_jax.evaluate import agent_params
    from foresit_jax.train import make_trainer

    info = rundir.read_run_info(run)
    config = Config(**info["config"])
    trainer = make_trainer(config)
    like = trainer.init(selection.run_key(info["seed"]))
    steps = [checkpoint.checkpoint_manager(run / name, 100).latest_step() for name in ("checkpoints", "best")]
    if None in steps:
        raise errors.UserError(f"{run} has no finished checkpoint (checkpoints/ and best/); train it to the end first")
    state = checkpoint.restore(checkpoint.checkpoint_manager(run / "checkpoints", 100), steps[0], like)
    selected = checkpoint.restore(checkpoint.checkpoint_manager(run / "best", 100), steps[1],
                                  agent_params(like, config.sigma2_max, config.evaluation_noise))  # fmt: skip
    state = state._replace(params=selected.params, imagination_params=selected.imagination_params)
    return {config.method: [Model(config, trainer, info["seed"], state, selected)]}


def models_of_sweep(folder: Path, methods: tuple[str, ...]) -> dict[str, list[Model]]:
    """{method: [Model per seed]} of a sweep's finished methods."""
    args = sweeps.saved(folder)
    finished = [m for m in args.methods if sweeps.finished_seeds(folder / "methods" / m)]
    unknown = [m for m in methods if m not in finished]
    if unknown:
        raise errors.UserError(f"{folder} has no finished {', '.join(unknown)}; finished: {', '.join(finished) or 'none'}")
    out = {}
    for method in methods or finished:
        config, _ = sweeps.method_schedule(method, args)
        if not methods and not (config.pieces.imagination_variant.uses_imagination or config.pieces.attention_critic):
            continue
        config, trainer, states, best = sweeps.load_method(method, args, folder / "methods" / method)
        seeds = sweeps.finished_seeds(folder / "methods" / method)
        out[method] = []
        for i, seed in enumerate(seeds):
            state, selected = jax.tree.map(lambda x: x[i], (states, best))
            state = state._replace(params=selected.params, imagination_params=selected.imagination_params)
            out[method].append(Model(config, trainer, seed, state, selected))
    return out
