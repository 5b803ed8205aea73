"""One update's loss, gradient and actions on fixed inputs, for the methods a redesign of the
network's routes must not change (issue 70's proof): `python -m benchmarks.fixed_update
--save tests/data/fixed_update.npz` writes them at the commit before the change, and
tests/agent/test_fixed_update.py compares the working tree's with that file.

Fixed inputs: tiny's network (32 units) in bathrooms, 4 lanes, the Trainer's initial
state from key 0, and its first window's acting key. What is kept per method: the window's
actions (exact), the loss, and per gradient leaf its norm and four projections onto fixed
random directions (a digest: a change of any entry moves them, and the file stays small).
A leaf is named by its path in the parameter tree; a redesign that renames a module maps
the old names to the new ones in the test.
"""

from __future__ import annotations

import argparse
import zlib
from pathlib import Path

import jax
import numpy as np

from foresit_jax.config import Config
from foresit_jax.methods import parse_method
from foresit_jax.train import make_trainer

TINY = dict(
    num_lanes=4,
    room_types=("bathroom",),
    hidden_size=32,
    attention_size=32,
    value_hidden=32,
    imagination_layer_sizes=(32, 16, 8, 16, 32, 32),
    buffer_size=2,
    imagination_epochs=1,
)

# (name, method, setup, Config fields of the arm)
ARMS = (
    ("a3c", "a3c", "savn", {}),
    ("a3c+foresit", "a3c+foresit", "savn", {}),
    ("a3c+foresit encoder", "a3c+foresit", "savn", {"imagination_input": "encoder"}),
    ("a3c+foresit mlp", "a3c+foresit", "savn", {"imagination_input": "mlp"}),
    ("a3c+critic", "a3c+critic", "savn", {}),
    ("a3c+oracle", "a3c+oracle", "savn", {}),
    ("a3c+maml+foresit", "a3c+maml+foresit", "savn", {}),
    ("a3c+org+foresit", "a3c+org+foresit", "org", {}),
    ("a3c+compass encoder", "a3c+compass", "savn", {"imagination_input": "encoder", "sigma2_max": 0.0}),
    ("a3c+optaction head", "a3c+optaction", "savn", {"sigma2_max": 0.0}),
)
PROJECTIONS = 4


def config_of(method: str, setup: str, fields: dict) -> Config:
    return Config(method=method, setup=setup, **{**TINY, **parse_method(method).required_config, **fields})


def directions(path: str, size: int) -> np.ndarray:
    """Fixed random directions for a leaf, from its name (the same in every process)."""
    return np.random.default_rng(zlib.crc32(path.encode())).standard_normal((PROJECTIONS, size))


def leaves(tree) -> dict[str, np.ndarray]:
    return {
        jax.tree_util.keystr(p): np.asarray(x, np.float64).ravel() for p, x in jax.tree_util.tree_leaves_with_path(tree)
    }


def fixed_update(config: Config) -> dict[str, np.ndarray]:
    """{"loss", "actions" [T, B], "leaves" (the gradient's leaf names), "digest" [leaves,
    1 + PROJECTIONS]: each leaf's norm and projections} of one update on fixed inputs."""
    trainer = make_trainer(config)
    state = trainer.init(jax.random.key(0))
    env = trainer.bind(trainer.env_params)
    actor, _, k_act = trainer.begin_window(state.actor, state.key, env)
    (loss, window), grads = jax.jit(trainer.loss_and_grad)(state.params, state.imagination_params, env, actor, k_act)
    flat = leaves(grads)
    digest = np.array([[np.linalg.norm(g), *(directions(path, g.size) @ g)] for path, g in flat.items()])
    return {
        "loss": np.float64(loss),
        "actions": np.asarray(window.traj.actions, np.int8),
        "leaves": np.array(list(flat)),
        "digest": digest,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--save", type=Path, required=True, help="the .npz to write")
    args = parser.parse_args()
    saved = {}
    for name, method, setup, fields in ARMS:
        for key, value in fixed_update(config_of(method, setup, fields)).items():
            saved[f"{name}|{key}"] = value
        print(name, "loss", float(saved[f"{name}|loss"]), flush=True)
    args.save.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(args.save, **saved)
    print(f"wrote {args.save} ({args.save.stat().st_size:,} bytes)")


if __name__ == "__main__":
    main()
