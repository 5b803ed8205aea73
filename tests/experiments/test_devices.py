"""experiments.running.devices: the sweep asks for two host devices, and seeds go to the most
devices that divide them."""

import os
from pathlib import Path

from experiments import sweep

REPO = Path(__file__).resolve().parents[2]


def test_the_sweep_command_asks_for_two_host_devices_unless_the_user_chose(monkeypatch):
    from experiments.running import devices

    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_use_thunk_runtime=true")
    devices.split_host_into_devices()
    expected = min(2, os.cpu_count() or 1)
    assert (
        os.environ["XLA_FLAGS"] == f"--xla_cpu_use_thunk_runtime=true --xla_force_host_platform_device_count={expected}"
    )
    monkeypatch.setenv("XLA_FLAGS", "--xla_force_host_platform_device_count=1")
    devices.split_host_into_devices()
    assert os.environ["XLA_FLAGS"] == "--xla_force_host_platform_device_count=1"
    import inspect

    assert "devices.split_host_into_devices()" in inspect.getsource(sweep.console)  # `foresit-sweep`
    assert "console()" in (REPO / "experiments" / "sweep.py").read_text().split("__main__")[-1]  # python -m


def test_seeds_go_to_the_most_devices_that_divide_them():
    from experiments.running import devices

    fake = ["d0", "d1", "d2", "d3"]
    assert [devices.seed_mesh(n, fake).devices.tolist() for n in (5, 6, 8, 3)] == [
        ["d0"],
        ["d0", "d1", "d2"],
        ["d0", "d1", "d2", "d3"],
        ["d0", "d1", "d2"],
    ]
