"""The command API's polled reads run in the real-time cycle's idle time (issue 32).

A `status` request costs the API thread ~0.3-1.3 ms of Python (the answer built and encoded as
JSON). The cycle thread shares the GIL with it: when the cycle wakes while the API thread holds
the GIL, it waits for it (up to the switch interval, more when the holder is in C), and that
wait is period error. Consoles poll on a multiple of the period (every 0.5 s is 25 cycles),
and a request that collided once ends when the cycle lets go of the GIL, so the next one falls
on the same phase of the cycle again: measured on an idle arm beside two CPU-bound processes
(load 3.6), status polled at 2 Hz made the 60 s window's period error p99 1.02 ms against
0.11 ms unpolled, and 12 of the 33 wakes later than 0.3 ms in two minutes began inside a
status request that had started ~0.85 ms before the deadline.

So a polled read waits, when it arrives while a cycle runs or less than GUARD before the next
deadline, until that cycle has ended: it then runs in the time the cycle sleeps. The wait is
at most MAX_WAIT, so a stalled cycle never stalls `status` (that is when an operator needs
it). Only the real-time clock has deadlines; in lockstep the gate is open.
"""
from __future__ import annotations

import threading
import time

GUARD = 0.004      # s before a deadline in which a read does not start (a read takes ~0.3-1.3 ms)
MAX_WAIT = 0.1     # s a read waits at most (5 cycles of 20 ms)


class IdleGate:
    def __init__(self, guard: float = GUARD, max_wait: float = MAX_WAIT):
        self.guard = guard
        self.max_wait = max_wait
        self._next_deadline: float | None = None   # monotonic; None: no deadlines (lockstep, not started)
        self._busy = False
        self._waiting = False
        self._ended = threading.Event()
        self.waits = 0             # reads that waited for a cycle's end

    # ---- the cycle's side: two stores a cycle, an Event only when a read waits ----------
    def cycle_started(self) -> None:
        self._busy = True

    def cycle_ended(self, next_deadline: float | None) -> None:
        self._next_deadline = next_deadline
        self._busy = False
        if self._waiting:
            self._waiting = False
            self._ended.set()

    # ---- the reader's side ---------------------------------------------------------------
    def _idle(self) -> bool:
        deadline = self._next_deadline
        return deadline is None or (not self._busy and deadline - time.monotonic() > self.guard)

    def wait_for_idle(self) -> None:
        """Return when the cycle is idle for at least GUARD, or after MAX_WAIT."""
        if self._idle():
            return
        self.waits += 1
        give_up = time.monotonic() + self.max_wait
        while not self._idle():
            left = give_up - time.monotonic()
            if left <= 0:
                return
            self._ended.clear()
            self._waiting = True
            if self._idle():           # the cycle ended between the look and the announcement
                self._waiting = False
                return
            self._ended.wait(left)
