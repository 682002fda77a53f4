"""A node whose TPDOs come after the real-time TPDO wait but before the next SYNC is slow, not
silent: the hardware interface names it `answered_late` and the supervisor ends its gap there.
A node that really falls silent is still stopped after missing_pdo_cycles, as before. Played on
the simulated nodes (firmware_sim) on the in-process bus, each SYNC answered after the read."""
from __future__ import annotations

import uuid

import numpy as np
import pytest

from spacearm.base.config.bus import load_bus_config
from spacearm.controller.daemon.hardware import CanopenHardware
from spacearm.controller.daemon.supervision import SupervisionLimits, Supervisor
from spacearm.firmware_sim.runner import Simulator


@pytest.fixture
def late_nodes():
    """(hardware, simulator, answer): the simulator holds every SYNC until answer() is called."""
    bus = f"virtual:late-answer-{uuid.uuid4().hex[:8]}"
    config = load_bus_config()
    sim = Simulator(bus, config).start()
    hw = CanopenHardware(bus, config, lockstep=False, realtime_budget=0.002)
    hw.start()
    hw.period = 60.0     # which data came is the point, not when: no read here counts as starved
    held = []
    answer_sync = sim._on_sync
    sim._on_sync = lambda: held.append(1)

    def answer():
        while held:
            held.pop()
            answer_sync()
    try:
        yield hw, sim, answer
    finally:
        hw.network.close()
        sim.stop()


def _pdo_missing(sup: Supervisor, m) -> list[str]:
    return [f.node for f in sup.check(m, None, False) if f.code == "pdo_missing"]


def test_late_answers_are_named_and_never_stop_the_arm(late_nodes):
    hw, sim, answer = late_nodes
    sup = Supervisor(SupervisionLimits(np.full(hw.dof, -10.0), np.full(hw.dof, 10.0), np.full(hw.dof, 100.0)),
                     hw.joint_names)
    nodes = sorted(hw.network.drivers)
    for k in range(3 * sup.limits.missing_pdo_cycles):
        m = hw.read(0.02 * k)
        assert sorted(m.missing) == nodes and not m.late          # nothing within the wait ...
        assert sorted(m.answered_late) == (nodes if k else [])    # ... but the last SYNC's data came
        assert _pdo_missing(sup, m) == []
        answer()                                                  # after the read, before the next SYNC
    assert hw.late_answers == len(nodes) * (3 * sup.limits.missing_pdo_cycles - 1)
    assert hw.statistics()["late_answers"] == hw.late_answers


def test_a_silent_node_among_late_ones_still_stops_after_missing_pdo_cycles(late_nodes):
    hw, sim, answer = late_nodes
    sup = Supervisor(SupervisionLimits(np.full(hw.dof, -10.0), np.full(hw.dof, 10.0), np.full(hw.dof, 100.0)),
                     hw.joint_names)
    for k in range(3):
        _pdo_missing(sup, hw.read(0.02 * k))
        answer()
    sim.node("joint_3").faults.silent = True
    stops = []
    for k in range(3, 3 + 2 * sup.limits.missing_pdo_cycles):
        m = hw.read(0.02 * k)
        assert ("joint_3" in m.answered_late) == (k == 3)     # its last answer was to the SYNC before
        assert len(m.answered_late) == len(hw.network.drivers) - (k > 3)
        stops.append(_pdo_missing(sup, m))
        answer()
    # the first read after the silence is the first of its gap: the stop comes at the limit's read
    first = next(k for k, found in enumerate(stops) if found)
    assert first == sup.limits.missing_pdo_cycles - 1 and stops[first] == ["joint_3"]


def test_a_measurement_names_every_field_as_its_dataclass_does(late_nodes):
    """hardware._measurement builds the frozen Measurement without its __init__ (cycle.built):
    every field in the class's order, the same object as Measurement(**fields)."""
    import dataclasses
    from spacearm.controller.cycle import Measurement
    hw, sim, answer = late_nodes
    m = hw.read(0.0)
    names = [f.name for f in dataclasses.fields(Measurement)]
    assert list(vars(m)) == names
    assert repr(m) == repr(Measurement(**{name: getattr(m, name) for name in names}))
