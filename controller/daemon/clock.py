"""Cycle clocks: real time on absolute deadlines, or lockstep as fast as the nodes answer.

Real time: cycle k is due at start + k * period. Waking late is period error; when a cycle
ran past the next deadline (an overrun) the missed deadlines are skipped, never run back
to back to catch up, and counted. Lockstep: no waiting at all; the caller paces the cycle
by waiting for every node's answer, and time advances by exactly one period per cycle.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable, Protocol


_new = object.__new__


@dataclass(frozen=True)
class Tick:
    cycle: int            # number of this cycle's deadline since start (gaps = skipped cycles)
    time: float           # the plant/controller time of this cycle, s (cycle * period)
    deadline: float       # monotonic deadline, s (lockstep: equals time)
    woke_at: float        # monotonic wake-up, s
    skipped: int          # deadlines skipped just before this tick because of an overrun

    @property
    def period_error(self) -> float:
        return self.woke_at - self.deadline


class CycleClock(Protocol):
    period: float

    def next_tick(self) -> Tick: ...


class RealTimeClock:
    def __init__(self, period: float, now: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep,
                 on_overrun: Callable[[float], None] | None = None):
        """on_overrun(missed_deadline): called the moment an overrun is found, before the sleep
        to the next deadline still ahead (controller/daemon/overrun_cause.py measures it)."""
        if not period > 0:
            raise ValueError(f"period must be positive, got {period}")
        self.period = period
        self._now = now
        self._sleep = sleep
        self.on_overrun = on_overrun
        self._start: float | None = None
        self._cycle = -1
        self.overruns = 0
        self.skipped_cycles = 0

    @property
    def next_deadline(self) -> float | None:
        """Monotonic time of the next deadline (in the past while a cycle overruns); None before the first tick."""
        return None if self._start is None else self._start + (self._cycle + 1) * self.period

    def next_tick(self) -> Tick:
        now = self._now()
        if self._start is None:
            self._start = now
            self._cycle = 0
            return Tick(0, 0.0, now, now, 0)
        cycle = self._cycle + 1
        deadline = self._start + cycle * self.period
        skipped = 0
        if now > deadline + self.period * 1e-3:
            # Still busy past the deadline we were heading for: the previous cycle overran.
            # Jump to the next deadline still ahead and count the ones missed.
            if self.on_overrun is not None:
                self.on_overrun(deadline)
            late_cycles = math.floor((now - deadline) / self.period) + 1
            skipped = late_cycles
            cycle += late_cycles
            deadline = self._start + cycle * self.period
            self.overruns += 1
            self.skipped_cycles += skipped
        wait = deadline - self._now()
        if wait > 0:
            self._sleep(wait)
        self._cycle = cycle
        return Tick(cycle, cycle * self.period, deadline, self._now(), skipped)


class LockstepClock:
    YIELD_INTERVAL = 0.02    # s of wall time between yields to the process's other threads

    def __init__(self, period: float, now: Callable[[], float] = time.monotonic):
        if not period > 0:
            raise ValueError(f"period must be positive, got {period}")
        self.period = period
        self._now = now
        self._cycle = -1
        self._last_yield = float("-inf")
        self.overruns = 0
        self.skipped_cycles = 0

    def next_tick(self) -> Tick:
        # With the in-process bus a lockstep cycle never blocks, and Python's locks are not
        # fair: without a yield, threads that share the simulator's or the master's send
        # lock (heartbeat producers, the API) can starve for hundreds of ms, and heartbeats
        # that are due in wall time go missing. A yield hands the GIL over and, on a loaded
        # host, often the CPU with it (~1 ms per call at load 7): so yield once per
        # YIELD_INTERVAL of wall time, not every cycle. That bounds the other threads' wait
        # (heartbeat periods are 100 ms) at a fraction of the cost.
        wall = self._now()
        if wall - self._last_yield >= self.YIELD_INTERVAL:
            time.sleep(0)
            wall = self._last_yield = self._now()
        self._cycle += 1
        # every cycle: the fields in Tick's order, without the frozen dataclass's __init__
        tick = _new(Tick)
        tick.__dict__.update({"cycle": self._cycle, "time": self._cycle * self.period, "deadline": wall,
                              "woke_at": wall, "skipped": 0})
        return tick
