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

from foresit_jax.agent import Agent
from foresit_jax.config import Config
from foresit_jax.evaluate import evaluate
from foresit_jax.methods import Method, parse_method
from foresit_jax.train import GridTrainer, Trainer, grid_inputs, make_train, make_trainer

__all__ = ["Agent", "Config", "GridTrainer", "Method", "Trainer", "evaluate", "grid_inputs", "make_train", "make_trainer",
           "parse_method"]
