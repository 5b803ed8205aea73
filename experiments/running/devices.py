"""Seeds spread over the local devices: a one-axis `Mesh` ("seed") and a `NamedSharding`
of the seed axis, so that one jitted, vmapped program runs each device's seeds on that
device (XLA partitions the program along the seed axis; nothing else changes).

A single device runs the same program. The number of devices used is the largest that
divides the number of seeds (5 seeds on 2 devices: 1 device), so that every device holds
as many seeds. On a CPU, `XLA_FLAGS=--xla_force_host_platform_device_count=N` (set
before jax starts) makes N host devices.

The mesh holds this process's devices (`jax.local_devices()`): on a cluster, run one sweep
per host, each with its own seeds (`--seed`). A mesh over every host's devices (after
`jax.distributed.initialize()`) would need each process to read back only the shards it
can address; that is not done here.
"""

from __future__ import annotations

import os

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec


# Measured with benchmarks.bench_devices on the 2-core CPU (a3c+foresit, quick, 4 seeds):
# 2 host devices ran the sweep's chunk 1.19x faster than 1 (6.94 vs 8.23 s per 20 updates).
DEFAULT_HOST_DEVICES = 2


def split_host_into_devices(count: int = DEFAULT_HOST_DEVICES) -> None:
    """Ask XLA for `count` host (CPU) devices (at most one per core), unless XLA_FLAGS
    already sets a count. Call it before jax's backends start (the sweep's command line
    does, first thing): afterwards it changes nothing. Accelerators are unaffected (their
    devices are jax's default ones); the host devices only matter where the CPU computes."""
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_force_host_platform_device_count" not in flags:
        count = max(1, min(count, os.cpu_count() or 1))
        os.environ["XLA_FLAGS"] = f"{flags} --xla_force_host_platform_device_count={count}".strip()


def memory_bytes() -> int:
    """The memory a run's seeds can use: the summed `bytes_limit` of the local accelerators
    where jax reports it, else the host's physical memory."""
    limits = [(d.memory_stats() or {}).get("bytes_limit", 0) for d in jax.local_devices() if d.platform != "cpu"]
    if limits and all(limits):
        return int(sum(limits))
    return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))


def seed_mesh(num_seeds: int, devices=None) -> Mesh:
    """A mesh over the most local devices that divide `num_seeds` evenly."""
    devices = list(jax.local_devices() if devices is None else devices)
    used = max(n for n in range(1, len(devices) + 1) if num_seeds % n == 0)
    return Mesh(np.array(devices[:used]), ("seed",))


def shard_seeds(tree, mesh: Mesh):
    """Place every leaf's leading (seed) axis across the mesh."""
    return jax.device_put(tree, NamedSharding(mesh, PartitionSpec("seed")))


def seed_slice(tree, i: int):
    """Seed i of a sharded tree, on the host (numpy): ready for single-device code."""
    return jax.device_get(jax.tree.map(lambda x: x[i], tree))
