"""In-process fixtures: the simulator and the controller on one python-can virtual bus."""
from __future__ import annotations

import time
import uuid

import pytest

from spacearm.base.config.bus import load_bus_config
from spacearm.drivers.network import ArmNetwork
from spacearm.firmware_sim.runner import Simulator


@pytest.fixture
def bus_config():
    return load_bus_config()


@pytest.fixture
def vbus():
    return f"virtual:canopen-{uuid.uuid4().hex[:8]}"


@pytest.fixture
def sim(vbus, bus_config):
    s = Simulator(vbus, bus_config).start()
    yield s
    s.stop()


@pytest.fixture
def net(vbus, bus_config, sim):
    n = ArmNetwork(vbus, bus_config)
    yield n
    n.close()


@pytest.fixture
def booted(net):
    net.boot()
    return net


@pytest.fixture
def enabled(booted):
    booted.enable_all()
    return booted


def eventually(predicate, timeout: float = 10.0, what: str = "condition"):
    """Wait for `predicate()` to hold. The timeout only ends a test that would otherwise hang
    (generous: the machine may be loaded); how fast it happens is measured in bench/, not here."""
    end = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > end:
            raise AssertionError(f"{what}: not reached within {timeout:.0f} s")
        time.sleep(0.005)
