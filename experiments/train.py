"""Train one agent: `python -m experiments.train --method a3c+foresit --preset quick --seed 0 --out runs/x`.

Shows a progress bar (updates, frames/s, success rate, ETA); writes per-update metrics
(JSONL and CSV), an orbax checkpoint after each chunk, a validation evaluation after each
chunk (the best model by validation SR is kept: model selection), and at the end the test
evaluation of the selected model (JSON and Markdown) and a learning-curve PNG.

`--resume` continues an interrupted run from its last intact checkpoint (a corrupt one is
skipped, saying so) and ends bit-identical to an uninterrupted run with the same seed on the
same platform (run.json records the platform of each stretch of updates, and a resume on
another one warns: `experiments.running.numerics`).  With `--resume`, `--num-updates` beyond the
run's extends it; any other flag that differs from the run's is refused (`resume_conflicts`);
a finished run is left as it is.  An existing run folder is never overwritten without
`--resume` or `--overwrite`, and one process at a time writes it (`rundir.claim`).  The loop
(chunks, the non-finite stop, where a resume continues) is the one `sweep` runs too:
`experiments.running.loop`.

Parameters and optimiser state are checked finite before every checkpoint: a run that
produced NaN or inf stops with an error naming its last finite checkpoint; a loss or
gradient norm far out of range, or a collapsed entropy, is warned of (`loop.divergence`).
"""

from __future__ import annotations

import dataclasses
import functools
import sys
import time
from pathlib import Path
from typing import Literal, Optional

import jax
import numpy as np

from experiments.reporting import figures, tables
from experiments.running import checkpoint, errors, loop, numerics, rundir, selection, tracking
from experiments.running.presets import Schedule, TrainConfigFields, config_flag, given, preset
from experiments.running.progress import progress_bar


@dataclasses.dataclass(frozen=True)
class Args:
    """Train one ForeSIT (or baseline) agent."""

    method: str = "a3c+foresit"
    """Method: '+'-joined pieces, e.g. a3c, a3c+foresit, a3c+rnd/att/int, a3c+critic, a3c+maml, a3c+maml+foresit,
    a3c+org, a3c+org+foresit; with Config fields of its own as METHOD@field=value,... (e.g.
    a3c+foresit@imagination_input=encoder)."""
    setup: str = "savn"
    """Environment setup: savn (first setup, word-vector targets) or org (second setup, detector features)."""
    preset: str = "quick"
    """Preset: tiny (seconds), quick (minutes on a laptop CPU), house (quick's learner in houses),
    paper (the paper's sizes)."""
    seed: int = 0
    """Random seed (same seed, same result, bit for bit, on the same machine)."""
    out: Path = Path("runs/x")
    """Run folder."""
    resume: bool = False
    """Continue the run in --out from its last checkpoint."""
    overwrite: bool = False
    """Delete an existing run in --out and start again."""
    num_updates: Optional[int] = None
    """Override the preset's number of updates."""
    num_lanes: Optional[int] = None
    """Override the preset's number of parallel lanes."""
    learning_rate: Optional[float] = None
    """Override the preset's learning rate."""
    chunk_updates: Optional[int] = None
    """Override the preset's updates per chunk (checkpoint/validation interval)."""
    test_episodes_per_room: Optional[int] = None
    """Override the preset's test episodes per room type."""
    val_episodes_per_room: Optional[int] = None
    """Override the preset's validation episodes per room type."""
    stop_after_chunks: Optional[int] = None
    """Stop (as if interrupted) after this many chunks of this invocation; for testing --resume."""
    progress: bool = True
    """Show the progress bar."""
    track: Literal["none", "tensorboard", "wandb"] = "none"
    """Also log the metrics and validations to TensorBoard (<out>/tensorboard) or Weights & Biases
    (offline without WANDB_API_KEY, <out>/wandb); needs pip install 'foresit_jax[track]'."""
    config: config_flag(TrainConfigFields) = dataclasses.field(default_factory=TrainConfigFields)
    """Every other Config field, e.g. --gamma 0.9 --room-types bathroom: the preset's value unless given."""


def build(args: Args):
    """Config and Schedule from the arguments (or from the run folder when resuming)."""
    overrides = dict(num_updates=args.num_updates, num_lanes=args.num_lanes, learning_rate=args.learning_rate,
                     setup=args.setup, **given(args.config))  # fmt: skip
    config, schedule = preset(args.preset, args.method, **overrides)
    sched = {k: getattr(args, k) for k in ("chunk_updates", "test_episodes_per_room", "val_episodes_per_room")}
    schedule = dataclasses.replace(schedule, **{k: v for k, v in sched.items() if v is not None})
    for name in ("chunk_updates", "test_episodes_per_room", "val_episodes_per_room"):
        if getattr(schedule, name) < 1:
            raise ValueError(f"{name} must be >= 1, got {getattr(schedule, name)}")
    return config, schedule


def resume_conflicts(args: Args, info: dict) -> list[str]:
    """The flags given with --resume (those not at their defaults: one at its default
    cannot be told from one not given) whose values differ from the run's, as
    `--flag value (the run has ...)`; --num-updates is not one (it extends the run)."""
    config, schedule = info["config"], info["schedule"]
    run = {"method": info.get("arm", info["method"]), "setup": config["setup"], "preset": info["preset"],
           "seed": info["seed"], "num_lanes": config["num_lanes"], "learning_rate": config["learning_rate"],
           **{k: schedule[k] for k in ("chunk_updates", "test_episodes_per_room", "val_episodes_per_room")}}  # fmt: skip
    defaults = Args()
    clash = [f"--{k.replace('_', '-')} {getattr(args, k)} (the run has {v})" for k, v in run.items()
             if getattr(args, k) != getattr(defaults, k) and getattr(args, k) != v]  # fmt: skip
    return clash + [f"--{k.replace('_', '-')} {v} (the run has {config[k]})" for k, v in given(args.config).items()
                    if rundir.jsonable(v) != config[k]]  # fmt: skip


def main(args: Args) -> dict:
    from foresit_jax.config import Config
    from foresit_jax.evaluate import Evaluator, agent_params
    from foresit_jax.train import make_trainer

    out = args.out
    tracking.check(args.track)
    if not args.resume:
        # Validate the arguments before touching --out (with --overwrite, a typo must not
        # delete the existing run and then fail).
        config, schedule = build(args)
    rundir.prepare_run_dir(out, args.resume, args.overwrite)
    if args.resume:
        info = rundir.read_run_info(out)
        selection.check_resumable(info.get("selection_protocol"), str(out))
        clash = resume_conflicts(args, info)
        if clash:
            raise errors.UserError(f"--resume continues {out} with its own settings; drop {', '.join(clash)} "
                                   "(only --num-updates may differ: it extends the run)")  # fmt: skip
        config = Config(**info["config"])
        schedule = Schedule(**info["schedule"])
        seed = info["seed"]
        if args.num_updates is not None and args.num_updates < config.num_updates:
            raise errors.UserError(f"--num-updates {args.num_updates} would shorten {out} ({config.num_updates} updates); "
                                   "--resume can only extend a run")  # fmt: skip
        if args.num_updates is not None and args.num_updates != config.num_updates:
            config = dataclasses.replace(config, num_updates=args.num_updates)
            print(f"extending {out} to {config.num_updates} updates (it had {info['config']['num_updates']})")
            info = {**info, "config": dataclasses.asdict(config)}
            rundir.write_run_info(out, info)
    else:
        seed = args.seed
        info = {"method": config.method, "arm": args.method, "preset": args.preset, "seed": seed,
                "config": dataclasses.asdict(config), "schedule": dataclasses.asdict(schedule),
                "selection_protocol": selection.PROTOCOL_VERSION, "numerics": numerics.extend(None, 0)[0]}  # fmt: skip
        rundir.write_run_info(out, info)

    trainer = make_trainer(config)
    env_params = trainer.env_params
    evaluator = Evaluator.for_config(config)  # held for the run: validation compiles once
    state = trainer.init(selection.run_key(seed))
    manager = checkpoint.checkpoint_manager(out / "checkpoints", schedule.keep_checkpoints)
    best_manager = checkpoint.checkpoint_manager(out / "best", 1)
    done = 0
    if args.resume and (out / "results_test.json").is_file() and (manager.latest_step() or 0) >= config.num_updates:
        print(f"{out} is finished ({config.num_updates} updates) and its results are written; nothing to do "
              "(pass --num-updates N to extend it)")  # fmt: skip
        return rundir.read_json(out / "results_test.json")["results"]
    if args.resume:
        done = loop.resume_point(manager, out / "checkpoints")
        if done:
            state = checkpoint.restore(manager, done, state)
            print(f"resuming {out} from update {done}")
        checkpoint.drop_steps_after(best_manager, done)  # a best model of those updates is chosen again
        # The platform of the updates still to come (experiments.running.numerics)
        history, warning = numerics.extend(numerics.rewind(info.get("numerics"), done), done)
        if history != info.get("numerics"):
            rundir.write_run_info(out, {**info, "numerics": history})
        if warning:
            print(f"warning: {warning}", file=sys.stderr, flush=True)
    rundir.truncate_rows(out / "metrics", done)
    rundir.truncate_rows(out / "validation", done)
    tracker = tracking.make(args.track, out, info)
    best = selection.Selection()
    for r in rundir.read_rows(out / "validation"):
        best.offer(r["SR"], r["update"])

    def validate_and_select(state, done: int) -> dict:
        """Validate after `done` updates; keep the model if it is the best so far."""
        params = agent_params(state, config.sigma2_max, config.evaluation_noise)
        val = selection.validate(evaluator, params, config, seed, schedule.val_episodes_per_room)
        rundir.append_rows(out / "validation", [{"update": done, **val["overall"]}])
        tracker.log([{"update": done, **val["overall"]}], prefix="validation/")
        if best.offer(val["overall"]["SR"], done):
            checkpoint.save(best_manager, done, params)
        return val

    # A run killed between a chunk's checkpoint and its validation, or between the
    # validation and saving the best model, is completed here (the keys depend only on
    # the seed: the same numbers as uninterrupted).
    if done and not any(r["update"] == done for r in rundir.read_rows(out / "validation")):
        validate_and_select(state, done)
    elif done and best.update == done and best_manager.latest_step() != done:
        checkpoint.save(best_manager, done, agent_params(state, config.sigma2_max, config.evaluation_noise))

    previous_rows = rundir.read_rows(out / "metrics")
    last_row = previous_rows[-1] if previous_rows else None
    total = config.num_updates
    bar = progress_bar(total, done, args.progress)
    # With the bar shown, the chunk moves it after every update (a host callback that reads
    # the update counter only: the same numbers).
    run_chunk = jax.jit(functools.partial(trainer.run, on_update=bar.at) if args.progress else trainer.run,
                        static_argnums=2)  # fmt: skip
    t_start = time.time()

    def after_chunk(state, chunk: loop.Chunk) -> None:
        """Record the chunk, checkpoint it, validate and select, move the bar."""
        nonlocal last_row
        rows = rundir.metric_rows(chunk.metrics, chunk.done - chunk.n, last_row)
        last_row = rows[-1]
        rundir.append_rows(out / "metrics", rows)
        tracker.log(rows)
        checkpoint.save(manager, chunk.done, state)
        val = validate_and_select(state, chunk.done)  # model selection on the validation split
        useful = float(np.sum(chunk.metrics["frames/useful"]))  # steps that entered the loss
        bar(chunk.n, {"useful fps": f"{useful / (time.time() - chunk.started):,.0f}",
                      "SR": f"{chunk.metrics['charts/success_rate'].mean():.3f}", "val SR": f"{val['overall']['SR']:.1f}%",
                      **({"warning": "diverging"} if chunk.warning else {})})  # fmt: skip

    state, done = loop.run_chunks(run_chunk, state, env_params, done=done, total=total,
                                  chunk_updates=schedule.chunk_updates, after_chunk=after_chunk, manager=manager,
                                  checkpoints=out / "checkpoints", budget=[args.stop_after_chunks])  # fmt: skip
    bar(0, None)
    tracker.close()
    if done < total:
        print(f"stopped after {args.stop_after_chunks} chunks at update {done} (resume with --resume)")
        return {"stopped_at": done}

    # Final test evaluation of the model selected on validation.
    best_step = best_manager.latest_step()
    chosen = checkpoint.restore(best_manager, best_step, agent_params(state, config.sigma2_max, config.evaluation_noise))
    test = evaluator.evaluate(chosen, config, "test", selection.test_key(seed), schedule.test_episodes_per_room)
    random = evaluator.evaluate_random_policy(config, "test", selection.test_key(seed), schedule.test_episodes_per_room)
    rundir.write_json(out / "results_test.json", {"selected_update": best_step, "results": test, "random_policy": random})
    title = f"{config.method}, preset {info['preset']}, seed {seed}: test split (model of update {best_step}, best validation SR)"
    report = tables.results_markdown(test, title) + "\n" + tables.results_markdown(random, "Uniformly random policy, same rooms", level=2)
    (out / "results_test.md").write_text(report)
    rows = rundir.read_rows(out / "metrics")
    x = np.array([r["update"] for r in rows])
    y = figures.smooth([r["charts/success_rate"] for r in rows])
    vals = [(r["update"], r["SR"] / 100.0) for r in rundir.read_rows(out / "validation")]
    figures.learning_curve_png(out / "learning_curve.png", {config.method: (x, y)}, val_points=vals)
    print(report)
    print(f"wrote {out}/results_test.md, results_test.json, learning_curve.png, metrics.csv "
          f"({time.time() - t_start:.0f} s)")  # fmt: skip
    return test


def cli(argv=None) -> None:
    errors.run_cli(Args, main, argv)


if __name__ == "__main__":
    cli(sys.argv[1:])
