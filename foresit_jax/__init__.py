"""foresit_jax: the ForeSIT agent (foresight sub-goal imagination) and its baselines in JAX.

The entry points (what the README uses):

    from foresit_jax import Config, make_train, Trainer, Agent, evaluate
    train = make_train(Config(method="a3c+foresit", num_lanes=16, num_updates=100))
    state, metrics = jax.jit(jax.vmap(train))(keys)     # a seed sweep in one program
    grid = GridTrainer(config)                           # learning rates vmapped too
    state, metrics = jax.jit(jax.vmap(grid.train))(*grid_inputs(seeds, [3e-4, 1e-3]))

The modules hold the pieces: `config` (Config), `methods` (base x encoder x imagination),
`networks` (flax modules), `lstm` (the encoder LSTM's split form), `agent` (acting),
`replay` (the replay gradient), `losses`, `imagination` (buffers, f_w training, noise),
`train` (the trainer), `evaluate` (SR/SPL on held-out scenes), `maml` (SAVN's inner loop),
`org` (ORG's object graph), `cvae` (the paper's C-VAE comparison).
"""

import importlib.util as _util
from pathlib import Path as _Path


def _check_envs() -> None:
    """The `envs` Python finds must be GridNav's, the package installed beside foresit_jax:
    `envs` is also a name on PyPI and a common local folder of RL repositories, and one
    shadowing it would fail deep inside an import. One line instead, naming what shadows it."""
    spec = _util.find_spec("envs")
    ours = _Path(__file__).resolve().parent.parent / "envs"
    found = None if spec is None or spec.origin is None else _Path(spec.origin).resolve().parent
    if found != ours:
        raise ImportError(
            f"foresit_jax needs GridNav's `envs` package ({ours}), but `import envs` finds "
            f"{found or 'nothing'}: a local envs/ folder or the PyPI package 'envs' shadows it; rename that folder, "
            "run from another directory, or `pip uninstall envs` (then reinstall foresit_jax)"
        )


_check_envs()

from foresit_jax.agent import Agent  # noqa: E402 (after the check of what `envs` is)
from foresit_jax.config import Config  # noqa: E402
from foresit_jax.evaluate import evaluate  # noqa: E402
from foresit_jax.methods import Method, parse_method  # noqa: E402
from foresit_jax.train import GridTrainer, Trainer, grid_inputs, make_train, make_trainer  # noqa: E402

__all__ = ["Agent", "Config", "GridTrainer", "Method", "Trainer", "evaluate", "grid_inputs", "make_train", "make_trainer",
           "parse_method"]
