"""The hardware interface marks a real-time cycle whose I/O ran late (the controller starved)
so its missing process data becomes a `late_cycle` event, while on-time misses stay evidence."""
from __future__ import annotations

import uuid

from spacearm.base.config.bus import load_bus_config
from spacearm.base.runtime.host_cpus import HostStallWatch
from spacearm.controller.cycle import FindingCode
from spacearm.controller.daemon.hardware import CanopenHardware
from spacearm.drivers.network import ArmState, NodeHealth


class _Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def _hardware(monkeypatch, clock: _Clock, wait: float) -> CanopenHardware:
    hw = CanopenHardware(f"virtual:unused-{uuid.uuid4().hex[:6]}", load_bus_config(), lockstep=False)
    net = hw.network
    health = {name: NodeHealth(name, d.node_id, alive=True) for name, d in net.drivers.items()}

    def wait_all(timeout):
        clock.t += wait                  # the TPDO wait as this process experienced it
        return False                     # ft_sensor's TPDO is missing

    monkeypatch.setattr(net, "send_sync", lambda: 1)
    monkeypatch.setattr(net, "wait_all_tpdos", wait_all)
    monkeypatch.setattr(net, "read", lambda complete, nodes=True, joints=True: ArmState(1, complete, [j.state() for j in net.joints],
                                                                None, None, health))
    monkeypatch.setattr(net, "poll_events", lambda: [])
    monkeypatch.setattr(net, "nodes_missing_tpdos", lambda: ["ft_sensor"])
    monkeypatch.setattr("spacearm.controller.daemon.hardware.time_module.monotonic", clock)
    hw.host_watch = HostStallWatch(lambda: ((clock.t * 100, 0), (clock.t * 100, 0)))   # both vCPUs run
    return hw


def test_on_time_cycle_with_missing_data_is_evidence(monkeypatch):
    clock = _Clock()
    hw = _hardware(monkeypatch, clock, wait=0.005)
    for _ in range(3):
        m = hw.read(0.0)
        clock.t += hw.period - 0.005     # next cycle on time
    assert m.missing == ("ft_sensor",) and not m.late
    assert not any(e.kind is FindingCode.LATE_CYCLE for e in m.events) and hw.late_cycles == 0


def test_starved_cycle_marks_late_and_reports_a_coded_event(monkeypatch):
    clock = _Clock()
    hw = _hardware(monkeypatch, clock, wait=0.005)
    hw.read(0.0)
    clock.t += 0.2                       # this process got no CPU for 10 periods
    m = hw.read(0.02)
    assert m.missing == ("ft_sensor",) and m.late
    late = [e for e in m.events if e.kind is FindingCode.LATE_CYCLE]
    assert len(late) == 1 and late[0].node == "ft_sensor" and hw.late_cycles == 1
    assert hw.statistics()["late_cycles"] == 1


def test_tpdo_wait_far_past_its_budget_is_late(monkeypatch):
    clock = _Clock()
    hw = _hardware(monkeypatch, clock, wait=0.05)   # asked for 5 ms, woke after 50 ms
    m = hw.read(0.0)
    assert m.late and hw.late_cycles == 1


def test_missing_data_while_the_host_holds_a_vcpu_is_a_coded_host_stall_event(monkeypatch):
    clock = _Clock()
    hw = _hardware(monkeypatch, clock, wait=0.005)
    hw.host_watch = HostStallWatch(lambda: ((int(clock.t * 100), 0), (10_000, 0)))   # vCPU 1 held
    stalls = []
    for _ in range(4):
        m = hw.read(0.0)
        clock.t += hw.period - 0.005     # this process on time
        stalls.append(m.host_stalled)
    assert stalls == [False, False, True, True] and not m.late
    event = [e for e in m.events if e.kind is FindingCode.HOST_STALL]
    assert len(event) == 1 and "vCPU 1" in event[0].detail and "ft_sensor" in event[0].detail
    assert hw.statistics()["host_stalled_cycles"] == 2


def test_a_stall_that_ends_before_it_shows_is_seen_in_the_first_complete_cycle(monkeypatch):
    """vCPU 1 held 60 ms: still for one sample only, then it counts its steal when it runs again,
    which the cycle whose data came back reads (and the next one no longer reads /proc/stat)."""
    clock = _Clock()
    hw = _hardware(monkeypatch, clock, wait=0.005)
    net = hw.network
    complete = iter([False, False, True, True])

    def wait_all(timeout):
        clock.t += 0.005
        return next(complete)
    monkeypatch.setattr(net, "wait_all_tpdos", wait_all)
    monkeypatch.setattr(net, "read", lambda c, nodes=True, joints=True: ArmState(1, c, [j.state() for j in net.joints], None, None,
                                                        {name: NodeHealth(name, d.node_id, alive=True)
                                                         for name, d in net.drivers.items()}))
    reads = []

    def stat():
        reads.append(clock.t)
        stolen = 6 if len(reads) >= 3 else 0
        return ((int(clock.t * 100), 0), (10_000 + stolen, stolen))
    hw.host_watch = HostStallWatch(stat)
    seen = []
    for _ in range(4):
        m = hw.read(0.0)
        clock.t += hw.period - 0.005
        seen.append(m.host_stalled)
    assert seen == [False, False, True, False] and len(reads) == 3
