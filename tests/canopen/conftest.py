"""In-process fixtures: the simulator and the controller on one python-can virtual bus."""
from __future__ import annotations

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
