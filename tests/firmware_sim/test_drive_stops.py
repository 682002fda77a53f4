"""The simulated CiA 402 drive stops as 605Ah/605Dh/605Eh say, judged from the positions it
reports: the ramp each option names (6084h slow-down, 6085h quick stop), from the joint's
speed (never faster), the state it ends in, and its power-off brake."""
from __future__ import annotations

import math
import uuid

import numpy as np
import pytest

from spacearm.base.canopen import od
from spacearm.base.canopen.cia402_defs import State
from spacearm.base.config.bus import load_bus_config
from spacearm.drivers.network import ArmCommand, ArmNetwork
from spacearm.firmware_sim.runner import Simulator

K = (1 << 20) * 100 / (2 * math.pi)     # increments per joint rad (configs/bus/arm.toml)
SLOW, QUICK = 0.2, 1.0                  # rad/s^2: 6084h, 6085h
SPEED = 0.15                            # rad/s
PERIOD = 0.02


@pytest.fixture
def arm():
    bus = f"virtual:stops-{uuid.uuid4().hex[:8]}"
    config = load_bus_config()
    sim = Simulator(bus, config).start()
    net = ArmNetwork(bus, config)
    try:
        net.boot()
        net.sdo_write("joint_1", od.PROFILE_DECELERATION, 0, round(SLOW * K))
        net.sdo_write("joint_1", od.QUICK_STOP_DECELERATION, 0, round(QUICK * K))
        net.enable_all()
        yield net, sim
    finally:
        net.close()
        sim.stop()


def _cruise(net) -> float:
    q = net.read().joints[0].position
    for _ in range(40):
        q += SPEED * PERIOD
        state = net.cycle(ArmCommand(joint_positions=[q], joint_velocities=[SPEED]))
    return state.joints[0].position


def _stop(net, cycles: int = 60) -> tuple[np.ndarray, list[State]]:
    """Cycles with the last target held (the drive must not chase it); positions and states."""
    positions, states = [], []
    for _ in range(cycles):
        s = net.cycle(ArmCommand(joint_velocities=[0.0]))
        positions.append(s.joints[0].position)
        states.append(s.joints[0].state)
    return np.array(positions), states


def _ramp(positions: np.ndarray) -> tuple[float, float]:
    """(peak speed, mean deceleration to rest) from the reported positions."""
    v = np.abs(np.diff(positions)) / PERIOD
    moving = np.flatnonzero(v > 0.01)
    return float(v.max()), float(v[0] / ((moving[-1] + 1) * PERIOD)) if moving.size else float("inf")


@pytest.mark.parametrize(("option", "deceleration", "final"), [
    (1, SLOW, State.SWITCH_ON_DISABLED), (2, QUICK, State.SWITCH_ON_DISABLED),
    (5, SLOW, State.QUICK_STOP_ACTIVE), (6, QUICK, State.QUICK_STOP_ACTIVE)])
def test_quick_stop_option_codes(arm, option, deceleration, final):
    net, sim = arm
    net.sdo_write("joint_1", od.QUICK_STOP_OPTION, 0, option)
    _cruise(net)
    net.quick_stop(0)
    positions, states = _stop(net, 80)
    peak, measured = _ramp(positions)
    assert peak <= SPEED * 1.05
    assert measured == pytest.approx(deceleration, rel=0.25)
    assert states[-1] == final
    assert sim.plant.joints[0].brake_engaged == (final == State.SWITCH_ON_DISABLED)
    assert all(j.enabled for j in net.read().joints[1:])


def test_halt_decelerates_on_the_slow_down_ramp_and_stays_enabled(arm):
    """605Dh is not in this drive's EDS: halt uses the slow-down ramp (option 1)."""
    net, sim = arm
    _cruise(net)
    net.joints[0].halt = True
    positions, states = _stop(net, 80)
    peak, measured = _ramp(positions)
    assert peak <= SPEED * 1.05 and measured == pytest.approx(SLOW, rel=0.25)
    assert states[-1] == State.OPERATION_ENABLED and not sim.plant.joints[0].brake_engaged


@pytest.mark.parametrize(("reaction", "at_rest_within"), [(2, 0.25), (0, 0.06)])
def test_fault_reaction_option(arm, reaction, at_rest_within):
    """605Eh 2: the quick-stop ramp, then fault and brake; 0: power off at once, the brake
    closes 30 ms later (the joint coasts until then)."""
    net, sim = arm
    net.sdo_write("joint_1", od.FAULT_REACTION_OPTION, 0, reaction)
    _cruise(net)
    sim.node("joint_1").inject_fault(0x5441)
    positions, states = _stop(net, 40)
    peak, _ = _ramp(positions)
    v = np.abs(np.diff(positions)) / PERIOD
    assert peak <= SPEED * 1.05
    assert np.all(v[int(round(at_rest_within / PERIOD)) + 1:] < 0.01)
    assert states[-1] == State.FAULT and sim.plant.joints[0].brake_engaged


def test_quick_stop_ramp_starts_from_the_joints_speed_not_the_interpolators(arm):
    """In CSP the reference's speed carries the velocity offset on top of the position steps
    (2x the joint's speed): a ramp from it sped the joint up to ~1.6x (issue 28)."""
    net, sim = arm
    _cruise(net)
    net.quick_stop(0)
    positions, _ = _stop(net, 30)
    peak, _ = _ramp(positions)
    assert peak <= SPEED * 1.05


def test_a_ramp_written_while_the_joint_moves_is_the_next_stops_ramp(arm):
    """The drive derives its per-SYNC settings once and keeps them while nothing is written
    (issue 35): a new 6085h and 605Ah written mid-motion still take effect at the next SYNC."""
    net, sim = arm
    net.sdo_write("joint_1", od.QUICK_STOP_OPTION, 0, 2)
    _cruise(net)                                   # the settings of the quick ramp are in use
    net.sdo_write("joint_1", od.QUICK_STOP_DECELERATION, 0, round(SLOW * K))
    net.sdo_write("joint_1", od.QUICK_STOP_OPTION, 0, 6)
    net.quick_stop(0)
    positions, states = _stop(net, 80)
    _, measured = _ramp(positions)
    assert measured == pytest.approx(SLOW, rel=0.25)
    assert states[-1] == State.QUICK_STOP_ACTIVE
