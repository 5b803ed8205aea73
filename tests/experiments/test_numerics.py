"""experiments.running.numerics: the platform recorded with a run, its history over a resumed run,
and the reports' Platforms section."""

from __future__ import annotations

import json

from experiments.running import numerics

CPUINFO = """processor	: 0
vendor_id	: AuthenticAMD
cpu family	: 25
model		: 17
model name	: AMD EPYC
flags		: fpu sse4_2 avx fma avx2 avx512f avx512bw

processor	: 1
vendor_id	: GenuineIntel
model name	: something else
"""
HERE = {
    "jax": "0.7.2",
    "jaxlib": "0.7.2",
    "backend": "cpu",
    "device": "cpu",
    "xla_flags": "",
    "cpu": {"name": "AMD EPYC", "vendor": "AuthenticAMD", "family": "25", "model": "17", "isa": "avx512"},
}
THERE = {**HERE, "cpu": {**HERE["cpu"], "isa": "avx2"}}


def test_isa_level_is_the_widest_instruction_set_the_flags_offer():
    assert numerics.isa_level({"sse4_2", "avx", "avx2", "fma", "avx512f"}) == "avx512"
    assert numerics.isa_level({"sse4_2", "avx", "avx2", "fma"}) == "avx2"
    assert numerics.isa_level({"sse4_2", "avx", "avx2"}) == "avx"  # AVX2 without FMA: XLA's AVX2 needs both
    assert numerics.isa_level({"sse4_2"}) == "sse4_2"
    assert numerics.isa_level({"neon"}) == "baseline"


def test_cpu_from_cpuinfo_reads_the_first_processor():
    assert numerics.cpu_from_cpuinfo(CPUINFO) == HERE["cpu"]


def test_xla_flags_drop_the_host_device_count_and_sort():
    flags = "--xla_force_host_platform_device_count=2 --xla_cpu_max_isa=AVX2 --xla_b=1"
    assert numerics.xla_flags(flags) == "--xla_b=1 --xla_cpu_max_isa=AVX2"
    assert numerics.xla_flags("--xla_force_host_platform_device_count=8") == ""


def test_fingerprint_is_json_and_ignores_only_the_device_count(monkeypatch):
    monkeypatch.delenv("XLA_FLAGS", raising=False)
    fp = numerics.fingerprint()
    assert json.loads(json.dumps(fp)) == fp
    assert fp["backend"] == "cpu" and fp["cpu"]["name"] and fp["xla_flags"] == ""
    monkeypatch.setenv("XLA_FLAGS", "--xla_force_host_platform_device_count=2")
    assert numerics.fingerprint() == fp
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_max_isa=AVX2")
    capped = numerics.fingerprint()
    assert capped != fp and "--xla_cpu_max_isa=AVX2" in numerics.describe(capped)


def test_describe():
    assert numerics.describe(HERE) == "cpu (AMD EPYC, AuthenticAMD family 25 model 17, avx512), jax 0.7.2"
    gpu = {"jax": "0.7.2", "jaxlib": "0.7.2", "backend": "gpu", "device": "NVIDIA H100", "xla_flags": "--x=1"}
    assert numerics.describe(gpu) == "gpu (NVIDIA H100), jax 0.7.2, XLA_FLAGS --x=1"
    assert numerics.describe(None) == "not recorded"


def test_extend_adds_a_stretch_only_where_the_platform_changes():
    fresh, warning = numerics.extend(None, 0, HERE)
    assert fresh == [{"from_update": 0, "platform": HERE}] and warning is None
    # Resumed on the same platform: nothing to add (a JSON round trip compares equal).
    same, warning = numerics.extend(json.loads(json.dumps(fresh)), 500, HERE)
    assert same == fresh and warning is None
    # Resumed elsewhere after 500 updates: a second stretch, and a warning naming both.
    moved, warning = numerics.extend(fresh, 500, THERE)
    assert moved == [*fresh, {"from_update": 500, "platform": THERE}]
    assert "updates 0-500" in warning and "avx512" in warning and "avx2" in warning and "uninterrupted" in warning
    # Killed before its first chunk and started elsewhere: that stretch trained nothing.
    assert numerics.extend(fresh, 0, THERE) == ([{"from_update": 0, "platform": THERE}], None)
    # A run that predates the record: its first stretch is "not recorded".
    old, warning = numerics.extend(None, 1000, HERE)
    assert old == [{"from_update": 0, "platform": None}, {"from_update": 1000, "platform": HERE}]
    assert "updates 0-1000 of this run recorded no platform" in warning


def per_seed(*histories):
    return [{"seed": i, "numerics": h} for i, h in enumerate(histories)]


def test_platforms_section_names_the_pairs_that_mix_platforms():
    here, there = numerics.extend(None, 0, HERE)[0], numerics.extend(None, 0, THERE)[0]
    one = numerics.markdown({"a": per_seed(here, here), "b": per_seed(here, here)}, [("a", "b")])
    assert f"Every method was trained on {numerics.describe(HERE)}." in one and "different platforms" not in one
    results = {
        "a": per_seed(here, here),
        "b": per_seed(here, here),
        "c": per_seed(there, there),
        "d": per_seed(None, None),
    }
    text = numerics.markdown(results, [("a", "b"), ("a", "c"), ("b", "d"), ("a", "missing")])
    assert f"- {numerics.describe(HERE)}: a, b\n" in text and f"- {numerics.describe(THERE)}: c\n" in text
    assert "- not recorded: d\n" in text
    assert "different platforms (or a run on several): a and c, b and d." in text
    # One run resumed elsewhere mixes platforms even against a method of its first one.
    resumed = numerics.extend(here, 500, THERE)[0]
    text = numerics.markdown({"a": per_seed(here), "b": per_seed(resumed)}, [("a", "b")])
    assert ": a and b." in text


def test_compiled_fast_turns_most_xla_optimisations_off_and_back_and_is_recorded():
    import jax
    import jax.numpy as jnp
    import numpy as np
    import pytest

    assert not numerics.fast_compile_on() and "xla_optimizations" not in numerics.fingerprint()
    f = jax.jit(lambda x: jnp.tanh(x) @ x.T)
    x = jnp.linspace(-1.0, 1.0, 12).reshape(3, 4)
    with numerics.compiled_fast(True):
        assert numerics.fast_compile_on()
        fp = numerics.fingerprint()
        assert fp["xla_optimizations"] == "most off" and "most XLA optimisations off" in numerics.describe(fp)
        np.testing.assert_allclose(jax.jit(lambda x: jnp.tanh(x) @ x.T)(x), f(x), rtol=1e-6)  # the same function
    assert not numerics.fast_compile_on()
    with pytest.raises(RuntimeError), numerics.compiled_fast(True):  # restored after an error too
        raise RuntimeError("boom")
    assert not numerics.fast_compile_on()
    with numerics.compiled_fast(False):
        assert not numerics.fast_compile_on()
