"""A vCPU the host holds (base/runtime/host_cpus.py) silences the nodes' process: seen live as a
vCPU that counts no CPU time while another does, or just after as a jump in its steal (what the
supervision does with it: test_supervision_late_cycles.py)."""
from __future__ import annotations

from spacearm.base.runtime.host_cpus import CLK_TCK, HostStallWatch

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
    assert watch.watching
    watch.reset()                                # data came: the next gap starts a new baseline
    assert not watch.watching
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
