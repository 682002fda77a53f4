"""The daemon's Measurement from the joints' readings (ArmState.readings, issue 35) is the one
from their JointStates, array for array and bit for bit."""
from __future__ import annotations

import random

from spacearm.base.canopen import od
from spacearm.base.config.bus import load_bus_config
from spacearm.drivers.network import ArmNetwork


def _tpdo_frames(net, rng):
    frames = []
    for d in net.drivers.values():
        for spec in d.tpdos:
            data = bytearray(rng.randrange(256) for _ in range(spec.length))
            if spec.entries[0].index == od.STATUSWORD:
                data[0:2] = rng.choice([0x0237, 0x0250, 0x0233, 0x0208, 0x0218, 0x0217]).to_bytes(2, "little")
            frames.append((spec.cob_id, bytes(data)))
    return frames


def test_the_measurement_from_readings_is_the_one_from_joint_states():
    """hardware._measurement's columns from ArmState.readings (the daemon's read) against the
    same ArmState of JointStates (read() by default, tests' doubles): the same arrays, bit for bit."""
    import numpy as np
    from spacearm.controller.daemon.hardware import CanopenHardware
    net = ArmNetwork("virtual:unused", load_bus_config())
    hardware = CanopenHardware.__new__(CanopenHardware)
    hardware.network = net
    rng = random.Random(1506)
    for _ in range(20):
        net.network.listeners[0].on_frames(_tpdo_frames(net, rng), 0.0)
        by_reading = hardware._measurement(1.0, 3, net.read(True, nodes=False, joints=False), ())
        by_state = hardware._measurement(1.0, 3, net.read(True, nodes=False), ())
        for name in ("q", "dq", "tau", "joints_enabled", "joints_faulted", "joints_powered"):
            a, b = getattr(by_reading, name), getattr(by_state, name)
            assert (a.dtype, a.shape, a.tobytes()) == (b.dtype, b.shape, b.tobytes()), name
        assert np.array_equal(by_reading.wrench, by_state.wrench)
