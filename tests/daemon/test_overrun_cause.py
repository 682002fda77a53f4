"""An overrun of the real-time cycle is judged by what its time went to: the host's steal first,
else the largest part (computing, the nodes' answers, a core, the GIL or another block)."""
from __future__ import annotations

import math
import threading
import time
import uuid

import pytest

from spacearm.base.runtime.host_cpus import CLK_TCK
from spacearm.controller.daemon.daemon import Daemon, DaemonOptions
from spacearm.controller.daemon.overrun_cause import OverrunMeter, judge
from spacearm.firmware_sim.runner import start_simulator

PERIOD = 0.02


@pytest.mark.parametrize("parts, cause", [
    (dict(compute=0.025, nodes=0.004, core=0.001, others=0.0, blocked=0.0, stolen=0.0), "compute"),
    (dict(compute=0.002, nodes=0.008, core=0.015, others=0.0, blocked=0.0, stolen=0.0), "core"),
    (dict(compute=0.002, nodes=0.004, core=0.001, others=0.030, blocked=0.035, stolen=0.0), "gil"),
    (dict(compute=0.002, nodes=0.004, core=0.001, others=0.002, blocked=0.035, stolen=0.0), "blocked"),
    (dict(compute=0.002, nodes=0.012, core=0.001, others=0.0, blocked=0.010, stolen=0.0), "nodes"),
    # a held vCPU looks like any wait inside the guest: the host is asked first
    (dict(compute=0.002, nodes=0.004, core=0.080, others=0.0, blocked=0.0, stolen=0.100), "host"),
])
def test_the_cause_is_the_host_first_then_the_largest_part(parts, cause):
    assert judge(lateness=0.05, **parts) == cause


def test_little_steal_does_not_make_an_overrun_the_hosts():
    assert judge(0.05, compute=0.06, nodes=0.0, core=0.0, others=0.0, blocked=0.0, stolen=0.02) == "compute"


class _Script:
    """A scripted cycle thread: wall clock, its CPU and run-queue delay, the process CPU, steal."""

    def __init__(self):
        self.wall = self.cpu = self.queue = self.process = 0.0
        self.steal = [0, 0]
        self.cycle = 0

    def advance(self, wall=0.0, cpu=0.0, queue=0.0, others=0.0, steal=0.0):
        self.wall += wall
        self.cpu += cpu
        self.queue += queue
        self.process += cpu + others
        self.steal[1] += round(steal * CLK_TCK)

    def meter(self) -> OverrunMeter:
        return OverrunMeter(steal=lambda: tuple(self.steal), now=lambda: self.wall,
                            thread_times=lambda: (self.cpu, self.queue), process_cpu=lambda: self.process)


def _run(script: _Script, meter: OverrunMeter, cycles: list[dict]) -> None:
    """Each entry: one cycle from the last one's end (deadline k * PERIOD): sleep to its
    deadline, then `work` as advance() arguments, with `nodes` s of TPDO wait in its wall."""
    for c in cycles:
        # an overrun skips the deadlines already past, as RealTimeClock does
        script.cycle = k = max(script.cycle + 1, math.ceil(script.wall / PERIOD - 1e-9))
        deadline = k * PERIOD
        script.wall = max(script.wall, deadline)
        work = dict(c.get("work", {}))
        work["wall"] = work.get("wall", 0.0) + c.get("nodes", 0.0)
        script.advance(**work)
        meter.end(k, deadline, deadline + PERIOD, c.get("nodes", 0.0))


def test_an_overrun_is_judged_a_cycle_later_with_its_parts():
    script = _Script()
    meter = script.meter()
    on_time = {"work": dict(wall=0.002, cpu=0.002), "nodes": 0.004}
    _run(script, meter, [on_time, on_time, {"work": dict(wall=0.030, cpu=0.029), "nodes": 0.004}])
    assert meter.pop_judged() == []          # judged once the guest has counted the steal
    _run(script, meter, [on_time] * 4)
    [overrun] = meter.pop_judged()
    assert overrun.cycle == 3 and overrun.cause == "compute"
    assert overrun.lateness == pytest.approx(0.014) and overrun.compute == pytest.approx(0.029)
    assert overrun.nodes == pytest.approx(0.004) and overrun.blocked == pytest.approx(0.001)
    assert "the controller's own computing" in overrun.describe()


ON_TIME = {"work": dict(wall=0.002, cpu=0.002), "nodes": 0.004}


def _after_on_time_cycles(n: int) -> tuple[_Script, OverrunMeter]:
    script = _Script()
    meter = script.meter()
    _run(script, meter, [ON_TIME] * n)
    return script, meter


def _late_wake(script: _Script, meter: OverrunMeter, cycle: int, delay: dict, counted_later: dict | None = None):
    """Cycle `cycle` wakes after `delay` (advance() arguments), does its usual 6 ms of work and
    ends; then three on-time cycles: the overruns judged meanwhile."""
    script.cycle, script.wall = cycle, cycle * PERIOD
    script.advance(**delay)
    script.advance(wall=0.006, cpu=0.002)
    meter.end(cycle, cycle * PERIOD, (cycle + 1) * PERIOD, 0.004)
    script.advance(**(counted_later or {}))
    _run(script, meter, [ON_TIME] * 3)
    return meter.pop_judged()


def test_a_late_wake_counts_what_delayed_it_and_the_sleep_is_planned_not_blocked():
    script, meter = _after_on_time_cycles(2)
    # cycle 3 wakes 25 ms late because another thread held the GIL, then does its usual work
    [overrun] = _late_wake(script, meter, 3, dict(wall=0.025, others=0.024))
    assert overrun.cause == "gil" and overrun.blocked == pytest.approx(0.025)


def test_a_held_vcpu_makes_the_overrun_the_hosts():
    script, meter = _after_on_time_cycles(6)
    # nothing of the process ran: the vCPU was held; the guest counts it once the vCPU runs again
    [overrun] = _late_wake(script, meter, 7, dict(wall=0.100), counted_later=dict(steal=0.100))
    assert overrun.cause == "host" and overrun.stolen == pytest.approx(0.1)


def test_time_lost_after_a_cycle_ended_on_time_is_judged_when_the_clock_finds_it():
    script, meter = _after_on_time_cycles(3)
    # cycle 3 ended on time; another thread then held the GIL 50 ms before the clock looked
    script.advance(wall=0.050, others=0.049)
    meter.overrun_found(4 * PERIOD)
    _run(script, meter, [ON_TIME] * 2)
    [overrun] = meter.pop_judged()
    assert overrun.cycle == 3 and overrun.cause == "gil"
    assert overrun.lateness == pytest.approx(3 * PERIOD + 0.006 + 0.050 - 4 * PERIOD)


def test_an_overrun_found_at_a_cycles_end_is_not_counted_again_by_the_clock():
    script = _Script()
    meter = script.meter()
    on_time = {"work": dict(wall=0.002, cpu=0.002), "nodes": 0.004}
    _run(script, meter, [on_time, {"work": dict(wall=0.030, cpu=0.029), "nodes": 0.004}])
    meter.overrun_found(3 * PERIOD)
    _run(script, meter, [ON_TIME] * 2)
    assert [o.cause for o in meter.pop_judged()] == ["compute"]


def test_on_time_cycles_are_never_judged():
    script = _Script()
    meter = script.meter()
    _run(script, meter, [{"work": dict(wall=0.010, cpu=0.006), "nodes": 0.008}] * 50)
    assert meter.pop_judged() == []


def test_a_real_time_daemon_names_its_own_computing_when_a_cycle_burns_the_cpu():
    """Live: one cycle of a real-time daemon computes 60 ms of its own thread's CPU. The overrun
    it causes is measured from /proc (the cycle thread's schedstat), so on a busy machine its
    run-queue delay may be as large; the judgement is then whichever part was larger."""
    bus = f"virtual:overrun-{uuid.uuid4().hex[:8]}"
    sim = start_simulator(bus, plant="configs/plant/oru_testbed_nominal.toml")
    daemon = Daemon(DaemonOptions(bus=bus, clock="realtime", api=None, record_dir=None))
    burn_at, burnt = 60, threading.Event()
    update = daemon.core.update

    def update_and_burn(m):
        if daemon.stats.cycles == burn_at:
            cpu = time.thread_time()
            while time.thread_time() - cpu < 0.060:
                pass
            burnt.set()
        return update(m)
    daemon.core.update = update_and_burn
    try:
        daemon.start()
        daemon.run(max_cycles=burn_at + 10)
    finally:
        daemon.shutdown()
        sim.stop()
    assert burnt.is_set()
    burnt_cycle = [o for o in daemon.overrun_log if o.compute >= 0.060]
    assert burnt_cycle, f"no judged overrun carries the burnt cycle's 60 ms of CPU: {daemon.overrun_log}"
    o = burnt_cycle[0]
    assert o.lateness >= 0.060 - PERIOD - 0.005     # it ran at least its CPU time, from a wake near its deadline
    expected = judge(o.lateness, o.compute, o.nodes, o.core, o.others, o.blocked, o.stolen)   # on the measured parts
    assert o.cause == expected and (o.cause == "compute" or o.core >= o.compute or o.stolen > 0), o.describe()
    assert daemon.stats.summary().overrun_causes.get(o.cause, 0) >= 1
