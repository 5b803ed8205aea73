"""Everything a training run computes, saved to compare two commits bit for bit (issue 82's
proof for a change that reorders the scan's carry, where `benchmarks.trace_update`'s hashes
must change): `python -m benchmarks.fingerprint --preset tiny --updates 20 --out before.npz`
at the commit before the change (`PYTHONPATH=<that checkout>`), the same at the commit after,
then `python -m benchmarks.fingerprint --compare before.npz after.npz`.

For each arm (`METHOD@field=value,...`, as `experiments.sweep` reads it; the object-graph
methods on the org setup) it trains `--updates` updates from seed 0 and keeps every leaf of
the final `RunnerState` and every metric of every update, named by its path. The lanes'
state is named by what each leaf is (`env_state`, `obs`, `lstm`, `prev_probs`, `episode_step`,
`imagined`, `s_0`, `tracker`, `memory`), so the layouts of ActorState before 0.4.0 (its
fields flat) and after it (the agent's carry and the imagination's nested) compare leaf
for leaf. `--compare` prints, per arm, the leaves compared and those that differ (any bit),
and exits 1 where one differs or is missing.
"""

from __future__ import annotations

import argparse
import sys
import time

import jax
import numpy as np

from experiments.running.presets import preset, split_arm
from foresit_jax.train import make_trainer

ARMS = (
    "a3c",
    "a3c+foresit",
    "a3c+foresit@imagination_input=encoder",
    "a3c+int",
    "a3c+oracle",
    "a3c+compass@sigma2_max=0",
    "a3c+maml+foresit",
    "a3c+org+foresit",
    "a3c@aux_target=compass,aux_weight=0.1",
    "a3c@aux_target=goal_view,aux_weight=0.1",
    "a3c@aux_target=success,aux_weight=0.1",
)

# What the lanes carry, by name, in either layout of ActorState.
LANE_FIELDS = ("lstm", "prev_probs", "episode_step", "imagined", "s_0", "tracker")


def lane_leaves(actor) -> dict:
    """The lanes' state as {name: subtree}, whichever layout `actor` has."""
    if hasattr(actor, "agent"):  # 0.4.0: env_state, obs, agent (lstm, prev_probs, episode_step, imagination), memory
        agent = actor.agent
        named = {
            "lstm": agent.lstm,
            "prev_probs": agent.prev_probs,
            "episode_step": agent.episode_step,
            "imagined": agent.imagination.imagined,
            "s_0": agent.imagination.s_0,
            "tracker": agent.imagination.tracker,
        }
    else:
        named = {f: getattr(actor, f) for f in LANE_FIELDS}
    return {"env_state": actor.env_state, "obs": actor.obs, "memory": actor.memory, **named}


def flat(prefix: str, tree) -> dict[str, np.ndarray]:
    leaves, _ = jax.tree_util.tree_flatten_with_path(tree)
    return {prefix + jax.tree_util.keystr(path): np.asarray(leaf) for path, leaf in leaves}


def fingerprint(arm: str, preset_name: str, updates: int) -> dict[str, np.ndarray]:
    method, _ = split_arm(arm)
    setup = "org" if "+org" in method else None
    config, _ = preset(preset_name, arm, num_updates=updates, setup=setup)
    trainer = make_trainer(config)
    state, metrics = jax.jit(trainer.train)(jax.random.PRNGKey(0))
    out = {}
    for field in state._fields:
        if field != "actor":
            out.update(flat(f"{arm}|{field}", getattr(state, field)))
    for name, sub in lane_leaves(state.actor).items():
        out.update(flat(f"{arm}|actor.{name}", sub))
    out.update(flat(f"{arm}|metrics", dict(metrics)))
    return out


def compare(before: str, after: str) -> int:
    a, b = np.load(before), np.load(after)
    arms = sorted({k.split("|")[0] for k in list(a.files) + list(b.files)})
    bad = 0
    for arm in arms:
        keys = sorted({k for k in list(a.files) + list(b.files) if k.split("|")[0] == arm})
        missing = [k for k in keys if k not in a.files or k not in b.files]
        differ = [
            k
            for k in keys
            if k not in missing
            and (a[k].shape != b[k].shape or a[k].dtype != b[k].dtype or a[k].tobytes() != b[k].tobytes())
        ]
        print(f"{arm}: {len(keys)} leaves, {len(differ)} differ, {len(missing)} missing")
        for k in (differ + missing)[:10]:
            print("   ", k)
        bad += len(differ) + len(missing)
    return 1 if bad else 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--preset", default="tiny")
    p.add_argument("--updates", type=int, default=20)
    p.add_argument("--arms", nargs="+", default=list(ARMS))
    p.add_argument("--out", help="the .npz to write")
    p.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"))
    args = p.parse_args(argv)
    if args.compare:
        return compare(*args.compare)
    if not args.out:
        p.error("give --out FILE.npz (or --compare BEFORE AFTER)")
    kept = {}
    for arm in args.arms:
        start = time.perf_counter()
        kept.update(fingerprint(arm, args.preset, args.updates))
        print(f"{arm}: {time.perf_counter() - start:.0f} s", flush=True)
    np.savez(args.out, **kept)
    return 0


if __name__ == "__main__":
    sys.exit(main())
