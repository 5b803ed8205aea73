"""foresit_jax: the ForeSIT agent (foresight sub-goal imagination) and its baselines in JAX.

The entry points (what the README uses):

    from foresit_jax import Config, make_train, make_act, evaluate_policy
    train = make_train(Config(method="a3c+foresit", num_lanes=16, num_updates=100))
    state, metrics = jax.jit(jax.vmap(train))(keys)     # a seed sweep in one program
    grid = GridTrainer(config)                           # learning rates vmapped too
    state, metrics = jax.jit(jax.vmap(grid.train))(*grid_inputs(seeds, [3e-4, 1e-3]))

The modules hold the pieces, from the ground up: `methods` (base x encoder x critic x
imagination, as flags), `config` (Config), `lstm` (the encoder LSTM and its split form),
`org` (ORG's object graph), `imagination` (buffers, f_w training, noise, f_w's loss),
`learned_loss` (SAVN's L_phi), `networks` (flax modules; `build(config)`), `rollout` (acting:
records and plain functions), `policy` (the agent step by step), `maml` (SAVN's inner loop
and the maml base's acting), `train` (the learner: returns, advantages and the A3C loss, the
update, Algorithm 1's imagination step, Trainer), `evaluate` (SR/SPL on held-out scenes; a
module: its function is `foresit_jax.evaluate.evaluate`). The studies' own functions over
the agent (the probes of i_tau, the paper's C-VAE comparison) are `experiments.analysis`.
"""

import importlib as _importlib
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

# The package face is lazy (PEP 562): `from foresit_jax.config import Config` loads the
# config and the method parser alone, and a name below loads its module when first used.
_EXPORTS = {
    "Config": "foresit_jax.config",
    "evaluate_policy": "foresit_jax.evaluate",
    "make_act": "foresit_jax.evaluate",
    "Method": "foresit_jax.methods",
    "parse_method": "foresit_jax.methods",
    "build": "foresit_jax.networks",
    "Networks": "foresit_jax.networks",
    "GridTrainer": "foresit_jax.train",
    "Trainer": "foresit_jax.train",
    "grid_inputs": "foresit_jax.train",
    "make_train": "foresit_jax.train",
    "make_trainer": "foresit_jax.train",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module 'foresit_jax' has no attribute {name!r}")
    value = getattr(_importlib.import_module(_EXPORTS[name]), name)
    globals()[name] = value  # once loaded, a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
