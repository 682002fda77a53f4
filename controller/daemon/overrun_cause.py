"""What a real-time cycle that ran past its next deadline (an overrun) spent its time on.

The cycle statistics count overruns; an operator needs to know why, because each cause has a
different cure: the controller's own computing (a slower algorithm), waiting for the nodes'
TPDOs (the bus or the simulator), waiting for a core (other processes, `--rt-priority`),
waiting for the GIL (another thread of this process held it: move that work out of the process),
or the host (the hypervisor held a vCPU: no priority helps).

Over the cycle, from the previous cycle's end to its own (so whatever delayed its wake counts),
the cycle thread was sleeping until its deadline (planned), running (its CPU time), runnable
without a core (its run-queue delay, Linux schedstat) or off the CPU otherwise: the TPDO
wait, measured by the hardware interface, or blocked: on the GIL when the process's
other threads ran meanwhile, else on a lock or I/O. The host's part is its steal of the most
stolen vCPU (/proc/stat) over the cycle; the guest counts steal only once a held vCPU runs again,
so the cycle's cause is judged one cycle later (SETTLE_CYCLES), over its own interval.
"""
from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass, replace
from typing import Callable

from spacearm.base.runtime.host_cpus import host_steal, stolen_since

SETTLE_CYCLES = 1     # judge an overrun this many cycles after it (the guest counts steal late)


@dataclass(frozen=True)
class CycleTimes:
    """One cycle thread's times at an instant; every field may be 0 where /proc cannot say."""
    wall: float       # s, monotonic
    own_cpu: float    # s, the cycle thread's CPU
    own_queue: float  # s, the cycle thread's run-queue delay so far
    process_cpu: float  # s, every thread of the process


@dataclass(frozen=True)
class Overrun:
    cycle: int
    lateness: float   # s past the next deadline
    compute: float    # s the cycle thread ran
    nodes: float      # s it waited for this SYNC's TPDOs
    core: float       # s it was runnable without a core
    others: float     # s the process's other threads ran meanwhile
    blocked: float    # s off the CPU other than the TPDO wait
    stolen: float     # s the host held the most stolen vCPU
    cause: str

    def describe(self) -> str:
        return (f"cycle {self.cycle} ran {1e3 * self.lateness:.1f} ms past its next deadline: {CAUSE_TEXT[self.cause]} "
                f"(computing {1e3 * self.compute:.1f} ms, waiting for the nodes {1e3 * self.nodes:.1f} ms, "
                f"for a core {1e3 * self.core:.1f} ms, blocked {1e3 * self.blocked:.1f} ms while other threads "
                f"ran {1e3 * self.others:.1f} ms; the host held a vCPU {1e3 * self.stolen:.0f} ms)")


CAUSE_TEXT = {
    "compute": "the controller's own computing",
    "nodes": "the nodes' answers came late",
    "core": "waited for a core (other processes or higher real-time priorities had them)",
    "gil": "waited for the GIL (another thread of the daemon held it)",
    "blocked": "blocked on a lock or I/O",
    "host": "the host did not run a vCPU (CPU steal; no priority helps)",
}


def judge(lateness: float, compute: float, nodes: float, core: float, others: float, blocked: float,
          stolen: float) -> str:
    """The overrun's cause: the host when it held a vCPU for half the lateness or more (inside the
    guest a stall looks like any other wait, so it is asked first); else the largest part of
    the cycle's time, a block counting as the GIL's when other threads ran for half of it."""
    if stolen >= lateness / 2:
        return "host"
    parts = {"compute": compute, "nodes": nodes, "core": core,
             "gil" if others >= blocked / 2 else "blocked": blocked}
    return max(parts, key=parts.get)


class _ThreadSchedstat:
    """The calling thread's (CPU s, run-queue s) from /proc/thread-self/schedstat; one descriptor
    per thread, read with pread (a cycle pays one read)."""

    def __init__(self):
        self._fd: int | None = None
        self._thread: int | None = None

    def read(self) -> tuple[float, float]:
        try:
            if self._thread != (ident := threading.get_native_id()):
                self.close()
                self._fd, self._thread = os.open("/proc/thread-self/schedstat", os.O_RDONLY), ident
            fields = os.pread(self._fd, 128, 0).split()
            return int(fields[0]) * 1e-9, int(fields[1]) * 1e-9
        except (OSError, ValueError, IndexError, TypeError):
            return time.thread_time(), 0.0

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


class OverrunMeter:
    """Call `end(cycle, deadline, next_deadline, nodes_wait)` when each real-time cycle has done
    its work, and let the clock call `overrun_found(deadline)` (RealTimeClock's on_overrun);
    `pop_judged()` returns the overruns judged since the last call. A cycle's interval
    runs from the previous cycle's end: it takes in the sleep until its deadline (taken out as
    planned) and whatever delayed its wake (a core, the GIL, the host).

    Costs one schedstat read and a process CPU read per cycle; /proc/stat (~0.2 ms) only at every
    STEAL_EVERY-th cycle and when an overrun is judged, so a cycle's steal is counted from up
    to STEAL_EVERY - 1 cycles before it: a host stall that ended just before the cycle began
    counts too, and it is what made the cycle wake late."""
    STEAL_EVERY = 5

    def __init__(self, steal: Callable[[], tuple[int, ...]] = host_steal,
                 now: Callable[[], float] = time.monotonic,
                 thread_times: Callable[[], tuple[float, float]] | None = None,
                 process_cpu: Callable[[], float] = time.process_time):
        self._steal, self._now, self._process_cpu = steal, now, process_cpu
        self._thread_times = thread_times or _ThreadSchedstat().read
        self._last: CycleTimes | None = None
        self._steal_base: tuple[int, ...] = ()
        self._pending: list[tuple[int, Overrun, tuple[int, ...]]] = []   # (cycles to settle, overrun, steal base)
        self._judged: list[Overrun] = []
        self._ends = self._cycle = 0
        self._late = False       # the last cycle's overrun is already counted

    def _times(self) -> CycleTimes:
        cpu, queue = self._thread_times()
        return CycleTimes(self._now(), cpu, queue, self._process_cpu())

    def end(self, cycle: int, deadline: float, next_deadline: float, nodes_wait: float) -> None:
        """`deadline`: this cycle's monotonic deadline; `next_deadline`: the one after it;
        `nodes_wait`: s of this cycle spent waiting for its TPDOs."""
        now, last = self._times(), self._last
        self._last = now
        self._settle()
        self._late = last is not None and now.wall > next_deadline
        if self._late:
            self._add(cycle, now.wall - next_deadline, last, now, max(0.0, deadline - last.wall), nodes_wait)
        self._cycle = cycle
        self._ends += 1
        if self._ends % self.STEAL_EVERY == 0 or not self._steal_base:
            self._steal_base = self._steal()

    def overrun_found(self, missed_deadline: float) -> None:
        """The clock found the deadline after the last cycle's already past: if that cycle's end
        was still on time, the time was lost between its end and the clock's look (a held GIL or
        vCPU); measured from that end, nothing of it planned."""
        last = self._last
        if last is None or self._late:
            return
        now = self._times()
        self._late = True
        self._add(self._cycle, now.wall - missed_deadline, last, now, 0.0, 0.0)

    def _add(self, cycle: int, lateness: float, last: CycleTimes, now: CycleTimes, planned_sleep: float,
             nodes_wait: float) -> None:
        compute = max(0.0, now.own_cpu - last.own_cpu)
        core = max(0.0, now.own_queue - last.own_queue)
        others = max(0.0, (now.process_cpu - last.process_cpu) - compute)
        blocked = max(0.0, (now.wall - last.wall) - planned_sleep - compute - core - nodes_wait)
        overrun = Overrun(cycle, lateness, compute, nodes_wait, core, others, blocked, 0.0, "")
        self._pending.append((SETTLE_CYCLES, overrun, self._steal_base))

    def _settle(self) -> None:
        """Judge the overruns whose steal the guest has had time to count."""
        if not self._pending:
            return
        pending, self._pending = self._pending, []
        now_steal = None
        for left, o, base in pending:
            if left > 1:
                self._pending.append((left - 1, o, base))
                continue
            now_steal = self._steal() if now_steal is None else now_steal
            stolen = stolen_since(base, now_steal) if base and now_steal else 0.0
            cause = judge(o.lateness, o.compute, o.nodes, o.core, o.others, o.blocked, stolen)
            self._judged.append(replace(o, stolen=stolen, cause=cause))

    def pop_judged(self) -> list[Overrun]:
        judged, self._judged = self._judged, []
        return judged
