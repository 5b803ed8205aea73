"""The platform a run's numbers were computed on, recorded beside them.

Training is deterministic on one platform: the same command gives the same numbers bit for
bit (the README's first command run twice on one machine: test SR 70.70% both times). Across
platforms it is not: XLA compiles for the machine it runs on (on a CPU, for its instruction
set, whose vector widths and fused multiply-adds round differently), and a run of thousands
of updates amplifies a last-bit difference into another training trajectory. Measured with
the same code and seed (the README's first command, a3c+foresit at quick): test SR 70.7% on an
AVX-512 machine, 58.7% on the same machine with XLA capped at AVX2
(`XLA_FLAGS=--xla_cpu_max_isa=AVX2`), 59.6% on another 2-core machine. The numbers are
draws from the same distribution, not errors; but a comparison "same seeds, same test
episodes" no longer pairs like with like when its two methods were trained on different
platforms, and a run resumed on another platform does not end with the numbers an
uninterrupted one would have.

So every run records the platform of each stretch of its updates (`extend`: progress.json
and results.json of every run folder, `train`'s and each arm's of a sweep), a run continued on
another platform says so, and reports list the platforms their methods were trained on
(`markdown`), naming the compared pairs that mix two.

What is recorded (`fingerprint`) is what decides the compiled code: jax and jaxlib, the
backend and device kind, on a CPU the processor (vendor, family, model and the widest vector
instruction set it offers) and XLA_FLAGS, without the host device count (spreading a sweep's
seeds over 2 host devices gives the numbers of 1: tests/experiments/test_sweep_cli.py). Two runs with
equal fingerprints have given equal numbers wherever we checked; unequal ones are not known to
differ, only not known to agree.
"""

from __future__ import annotations

import contextlib
import platform
import re
from pathlib import Path

# x86 vector instruction sets, widest first: the first one whose flags a CPU has is its level.
ISA_LEVELS = (("avx512", ("avx512f",)), ("avx2", ("avx2", "fma")), ("avx", ("avx",)), ("sse4_2", ("sse4_2",)))
DEVICE_COUNT_FLAG = re.compile(r"--xla_force_host_platform_device_count=\S*")


def isa_level(flags: set[str]) -> str:
    """The widest x86 vector instruction set of a CPU with these /proc/cpuinfo flags."""
    return next((name for name, needs in ISA_LEVELS if all(f in flags for f in needs)), "baseline")


def cpu_from_cpuinfo(text: str) -> dict:
    """The processor of a Linux /proc/cpuinfo (its first one): model name, vendor, family,
    model and ISA level."""
    fields = {}
    for line in text.splitlines():
        if not line.strip():
            break  # the first processor only: the others are the same chip
        key, _, value = line.partition(":")
        fields[key.strip()] = value.strip()
    cpu = {
        k: fields.get(key, "")
        for k, key in (("name", "model name"), ("vendor", "vendor_id"), ("family", "cpu family"), ("model", "model"))
    }
    if "flags" in fields:
        cpu["isa"] = isa_level(set(fields["flags"].split()))
    return cpu


def host_cpu() -> dict:
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        return cpu_from_cpuinfo(cpuinfo.read_text(errors="replace"))
    return {"name": platform.processor() or platform.machine(), "machine": platform.machine()}


def xla_flags(flags: str) -> str:
    """XLA_FLAGS without the host device count, normalised (sorted flags)."""
    return " ".join(sorted(DEVICE_COUNT_FLAG.sub("", flags).split()))


FAST_COMPILE_FLAG = "jax_disable_most_optimizations"


def fast_compile_on() -> bool:
    """Whether this process compiles with most of XLA's optimisations off (`compiled_fast`)."""
    import jax

    return bool(jax.config.read(FAST_COMPILE_FLAG))


@contextlib.contextmanager
def compiled_fast(on: bool):
    """Compile what runs inside with most of XLA's optimisations off (jax's
    `jax_disable_most_optimizations`: backend optimisation level 0, no expensive LLVM passes)
    when `on`, and restore the setting after. Programs compile in a fraction of the time and
    run slower, and their floating-point results can differ from a normally compiled
    program's in the last bits (a platform of its own: `fingerprint` records it). For smoke
    runs, where compiling is most of the time (`experiments.paper --preset tiny`)."""
    import jax

    before = fast_compile_on()
    jax.config.update(FAST_COMPILE_FLAG, bool(on))
    try:
        yield
    finally:
        jax.config.update(FAST_COMPILE_FLAG, before)


def fingerprint() -> dict:
    """This process's platform, as recorded with a run (JSON values only)."""
    import os

    import jax
    import jaxlib

    backend = jax.default_backend()
    fp = {
        "jax": jax.__version__,
        "jaxlib": jaxlib.__version__,
        "backend": backend,
        "device": jax.devices()[0].device_kind,
        "xla_flags": xla_flags(os.environ.get("XLA_FLAGS", "")),
    }
    if backend == "cpu":
        fp["cpu"] = host_cpu()
    if fast_compile_on():  # only then: a fingerprint of a normal compile stays as it was
        fp["xla_optimizations"] = "most off"
    return fp


def describe(fp: dict | None) -> str:
    """One line for a fingerprint (None: a stretch run before platforms were recorded)."""
    if fp is None:
        return "not recorded"
    cpu = fp.get("cpu")
    if cpu:
        chip = ", ".join(
            x
            for x in (
                cpu.get("name"),
                cpu.get("vendor") and f"{cpu['vendor']} family {cpu.get('family')} model {cpu.get('model')}",
                cpu.get("isa"),
            )
            if x
        )
        where = f"cpu ({chip})"
    else:
        where = f"{fp['backend']} ({fp['device']})"
    flags = f", XLA_FLAGS {fp['xla_flags']}" if fp.get("xla_flags") else ""
    fast = ", most XLA optimisations off" if fp.get("xla_optimizations") else ""
    return f"{where}, jax {fp['jax']}{flags}{fast}"


def extend(history: list | None, done: int, here: dict | None = None) -> tuple[list, str | None]:
    """The platform history of a run about to train from update `done` on this platform
    (`here`, default `fingerprint()`): `history` (a list of {"from_update", "platform"}, or
    None for a run that recorded none) with this platform's stretch added when it differs
    from the last one. Returns (the history, a warning to show or None)."""
    here = fingerprint() if here is None else here
    if not history:
        if done == 0:
            return [{"from_update": 0, "platform": here}], None
        history = [{"from_update": 0, "platform": None}]
    last = history[-1]
    if last["platform"] == here:
        return history, None
    kept = history[:-1] if last["from_update"] == done else history  # that stretch trained nothing
    if last["platform"] is None:
        warning = (
            f"updates {last['from_update']}-{done} of this run recorded no platform; if they were trained on "
            f"another one than this ({describe(here)}), the run will not end with the numbers of an "
            "uninterrupted run"
        )
    else:
        warning = (
            f"continuing on another platform than updates {last['from_update']}-{done} were trained on "
            f"({describe(last['platform'])}; here {describe(here)}): from update {done} on this run follows "
            "this platform's rounding, so it will not end with the numbers of an uninterrupted run"
        )
    return kept + [{"from_update": done, "platform": here}], (warning if done else None)


def rewind(history: list | None, done: int) -> list | None:
    """`history` as it was when the run had trained `done` updates (a resume that falls
    back to an earlier checkpoint): the stretches that began after it are dropped."""
    return [h for h in history if h["from_update"] <= done] or None if history else history


def platforms_of(history: list | None) -> list[str]:
    """The descriptions of a run's platforms, in order (a run that recorded none: one
    'not recorded')."""
    return [describe(h["platform"]) for h in history] if history else [describe(None)]


def markdown(results_by_method: dict[str, list[dict]], pairs) -> str:
    """A report's "Platforms" section: which platforms trained which methods (from each seed's
    result's "numerics" history), and which of the compared `pairs` (method, method) mix
    platforms, whose paired differences then include the platforms' effect."""
    trained = {
        m: sorted({p for r in per_seed for p in platforms_of(r.get("numerics"))})
        for m, per_seed in results_by_method.items()
    }
    names = sorted({p for ps in trained.values() for p in ps})
    lines = [f"- {p}: {', '.join(m for m, ps in trained.items() if p in ps)}" for p in names]
    text = "## Platforms\n\n" + (
        f"Every method was trained on {names[0]}.\n"
        if len(names) == 1
        else "Methods were trained on these platforms:\n\n" + "\n".join(lines) + "\n"
    )
    mixed = [
        (a, b) for a, b in pairs if a in trained and b in trained and (trained[a] != trained[b] or len(trained[a]) > 1)
    ]
    if mixed:
        text += (
            "\nTrained on different platforms (or a run on several): "
            + ", ".join(f"{a} and {b}" for a, b in mixed)
            + ". Their paired differences compare trajectories of different rounding, not only different "
            "methods: a platform moves one seed's result as much as another seed does (`experiments/running/numerics.py`).\n"
        )
    return text
