"""The arm with two drive models on one bus (configs/bus/arm_mixed.toml): the standard joint
drive and a compact drive with its own EDS (1 RPDO, 2 TPDOs, no 1016h, read-only scaling)."""
from __future__ import annotations

import math

import pytest

from spacearm.base.canopen import od
from spacearm.base.config.bus import load_bus_config
from spacearm.drivers.network import ArmNetwork
from spacearm.firmware_sim.runner import Simulator

MIXED = load_bus_config.__defaults__[0].parent / "arm_mixed.toml"


@pytest.fixture
def mixed(vbus):
    cfg = load_bus_config(MIXED)
    sim = Simulator(vbus, cfg).start()
    net = ArmNetwork(vbus, cfg)
    yield net, sim
    net.close()
    sim.stop()


def test_mixed_drives_boot_with_each_drives_own_description(mixed):
    net, _ = mixed
    net.boot()
    compact, standard = net.bringup["joint_5"], net.bringup["joint_2"]
    assert "no 1016h" in compact.guarding and "1016h" in standard.guarding
    assert "0x608F:01=131072" in compact.read_only and "0x6091:01=160" in compact.read_only
    assert standard.read_only == []
    assert net.joints[4].k == pytest.approx((1 << 17) * 160 / (2 * math.pi))
    assert net.joints[1].k == pytest.approx((1 << 20) * 100 / (2 * math.pi))
    mapped = [net.sdo_read("joint_5", od.TPDO_MAP + 1, i) >> 16 for i in range(1, 4)]
    assert mapped == [od.VELOCITY_ACTUAL, od.TORQUE_ACTUAL, od.ERROR_CODE]     # its default mapped 2000h


def test_mixed_arm_enables_and_tracks_a_joint_move(mixed):
    net, sim = mixed
    net.boot()
    start = net.enable_all().joint_positions
    goal = [q + 0.1 * (-1) ** i for i, q in enumerate(start)]
    state = net.move_to(goal, 1.0, settle_cycles=25)
    for joint, q, g in zip(state.joints, state.joint_positions, goal):
        assert q == pytest.approx(g, abs=2e-3), joint.name
    # the compact drive counts in its own increments
    assert sim.node("joint_6").get(od.POSITION_ACTUAL) == pytest.approx(goal[5] * net.joints[5].k, abs=3e-3 * net.joints[5].k)
    net.set_mode("joint_4", od.MODE_PROFILE_POSITION)                    # 6060h by SDO: not in its RPDO
    assert net.sdo_read("joint_4", od.MODES_OF_OPERATION) == od.MODE_PROFILE_POSITION


def test_compact_drive_heartbeat_loss_is_detected_by_the_master(mixed):
    net, sim = mixed
    net.boot()
    net.poll_events()
    sim.node("joint_4").faults.heartbeat_stopped = True
    import time
    deadline = time.monotonic() + 1.0
    lost = []
    while time.monotonic() < deadline and not lost:
        time.sleep(0.02)
        lost = [e for e in net.poll_events() if e.kind == "heartbeat_lost"]
    assert lost and lost[0].node == "joint_4"
