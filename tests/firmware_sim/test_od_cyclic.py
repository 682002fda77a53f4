"""The objects a device writes every SYNC through its precompiled layout (firmware_sim/od_cyclic.py)
hold what put() would have stored: an unchanged value is not written again, yet a value that
someone else stored in between is overwritten at the next SYNC; a value that does not fit is
one line naming the object."""
from __future__ import annotations

import pytest

from spacearm.base.canopen import od
from spacearm.base.config.bus import load_bus_config
from spacearm.firmware_sim.od_cyclic import CyclicObjects
from spacearm.firmware_sim.runner import Simulator


@pytest.fixture
def drive():
    sim = Simulator("virtual:unused", load_bus_config())    # never started: no bus, the nodes by hand
    node = sim.node("joint_1")
    node.power_on()
    return sim, node


def sync(sim) -> None:
    for node in sim.nodes.values():
        node.on_sync_begin(0.02)
    sim.plant.step(0.02)
    for node in sim.nodes.values():
        node.on_sync_end(0.02)


def test_a_statusword_stored_by_someone_else_is_the_drives_again_after_one_sync(drive):
    sim, node = drive
    for other in sim.nodes.values():
        other.power_on()
    sync(sim)
    statusword = node.get(od.STATUSWORD)
    node.put(od.STATUSWORD, 0, 0)
    assert node.get(od.STATUSWORD) == 0
    sync(sim)
    assert node.get(od.STATUSWORD) == statusword


def test_the_layout_stores_the_bytes_put_stores_and_drops_the_param_cache(drive):
    _, node = drive
    objects = [(od.POSITION_ACTUAL, 0), (od.TORQUE_ACTUAL, 0)]
    node.param(od.POSITION_ACTUAL)
    CyclicObjects(node, objects).write((-123456, -42))
    assert node.param(od.POSITION_ACTUAL) == -123456
    via_layout = [node.raw(*o) for o in objects]
    node.put(od.POSITION_ACTUAL, 0, -123456)
    node.put(od.TORQUE_ACTUAL, 0, -42)
    assert [node.raw(*o) for o in objects] == via_layout


def test_a_value_that_does_not_fit_is_one_line_naming_the_object(drive):
    _, node = drive
    layout = CyclicObjects(node, [(od.TORQUE_ACTUAL, 0)])
    with pytest.raises(ValueError, match=r"^0x6077:00: 40000 does not fit <h$"):
        layout.write((40000,))
