"""A vCPU the host holds (base/runtime/host_cpus.py) silences the nodes' process: seen live as a
vCPU that counts no CPU time while another does, or just after as a jump in its steal. Missing
data in such cycles is held, not counted, a bounded number of times; a real loss still stops."""
from __future__ import annotations

import numpy as np

from spacearm.base.runtime.host_cpus import CLK_TCK, HostStallWatch
from spacearm.controller.cycle import FindingCode, Measurement
from spacearm.controller.daemon.supervision import HOST_CYCLES_EXCUSED, SupervisionLimits, Supervisor

TICK = 1.0 / CLK_TCK


class ProcStat:
    """Two vCPUs' (all times, steal) in ticks; `run(dt, held=...)` lets time pass."""
    def __init__(self, cpus: int = 2):
        self.times = [[1000, 0] for _ in range(cpus)]

    def run(self, dt: float, held: int | None = None, steal_on_return: int | None = None) -> None:
        for i, row in enumerate(self.times):
            if i != held:
                row[0] += round(dt / TICK)
        if steal_on_return is not None:      # the held vCPU accounts its steal when it runs again
            self.times[steal_on_return][0] += 1
            self.times[steal_on_return][1] += round(0.1 / TICK)

    def __call__(self):
        return tuple(tuple(row) for row in self.times)


def sampled(stat: ProcStat, cycles: int, held: int | None, t0: float, watch: HostStallWatch) -> list[bool]:
    seen = []
    for k in range(cycles):
        stat.run(0.02, held)
        seen.append(watch.sample(t0 + 0.02 * (k + 1)))
    return seen


def test_a_vcpu_that_counts_no_time_while_another_does_is_held_by_the_host():
    stat = ProcStat()
    watch = HostStallWatch(stat)
    watch.sample(0.0)
    assert sampled(stat, 10, None, 0.0, watch) == [False] * 10       # both count: nothing held
    seen = sampled(stat, 5, 1, 0.2, watch)
    # 20 ms still is one missed tick; from 40 ms (two samples) it is the host
    assert seen == [False, True, True, True, True]
    assert "vCPU 1" in watch.held and "100 ms" in watch.held
    stat.run(0.02, steal_on_return=1)            # it runs again and counts its 100 ms of steal
    assert watch.sample(0.32) and "100 ms (CPU steal)" in watch.held
    stat.run(0.02)
    assert watch.sample(0.34)                    # its processes catch up: still the stall's
    stat.run(0.02)
    assert watch.sample(0.36)
    stat.run(0.02)
    assert not watch.sample(0.40) and watch.held == ""
    watch.reset()                                # data came: the next gap starts a new baseline
    stat.run(0.02, held=0)
    assert not watch.sample(0.42)
    stat.run(0.02, held=0)
    assert not watch.sample(0.44)                # 20 ms still since the baseline: one tick's doubt
    stat.run(0.02, held=0)
    assert watch.sample(0.46) and "vCPU 0" in watch.held


def test_every_vcpu_still_is_this_process_paused_not_the_host_holding_one():
    stat = ProcStat()
    watch = HostStallWatch(stat)
    watch.sample(0.0)
    assert not watch.sample(0.1)                 # nothing counted anywhere: our own clock jumped
    assert not any(sampled(stat, 5, None, 0.1, watch))


def test_one_vcpu_cannot_tell_and_says_nothing():
    stat = ProcStat(cpus=1)
    watch = HostStallWatch(stat)
    assert not any(sampled(stat, 10, 0, 0.0, watch))
    assert not HostStallWatch(lambda: ()).sample(1.0)      # no /proc/stat


def measurement(missing: tuple[str, ...], host_stalled: bool) -> Measurement:
    n = 2
    return Measurement(time=0.0, sync_counter=0, q=np.zeros(n), dq=np.zeros(n), tau=np.zeros(n),
                       joints_enabled=np.ones(n, bool), joints_faulted=np.zeros(n, bool), wrench=np.zeros(6),
                       missing=missing, host_stalled=host_stalled)


def supervisor() -> Supervisor:
    return Supervisor(SupervisionLimits(np.full(2, -3.0), np.full(2, 3.0), np.ones(2)), ["j1", "j2"])


def first_stop(pattern: list[bool], sup: Supervisor) -> int | None:
    for k, stalled in enumerate(pattern, 1):
        if any(f.code is FindingCode.PDO_MISSING for f in sup.check(measurement(("joint_1",), stalled), None, False)):
            return k
    return None


def test_a_100_ms_host_stall_is_no_node_loss_but_a_node_lost_in_one_still_stops():
    sup = supervisor()
    limit = sup.limits.missing_pdo_cycles
    # the stall seen from the second silent cycle on, ~100 ms, then its catch-up cycles
    stall = [False] + [True] * 7
    assert first_stop(stall, sup) is None and sup.host_cycles_excused == 7
    sup.check(measurement((), False), None, False)           # the data came back: a new gap
    assert first_stop(stall * 3, supervisor()) is not None    # one endless gap is bounded ...
    assert first_stop([True] * 40, supervisor()) == limit + HOST_CYCLES_EXCUSED
    assert limit + HOST_CYCLES_EXCUSED <= 15                 # ... by 300 ms at 20 ms
    # and every stall gets its own excuse: ten stalls, each followed by the data, never stop
    sup = supervisor()
    for _ in range(10):
        assert first_stop(stall, sup) is None
        sup.check(measurement((), False), None, False)
    assert first_stop([False] * limit, sup) == limit          # a silent node with no stall: as ever
