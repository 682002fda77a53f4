"""The simulator's and the hub's own lateness, as they publish it on the bus.

The daemon can only see that answers come late; it cannot tell a starved simulator from a
starved hub or a slow drive. So each of them measures its own scheduler (how late its timer
wakes) and says so, the way a CANopen device reports its status: an asynchronous TPDO of a
diagnostics node ID, sent on its event timer (once a second, so the master learns "still on
time" too and notices when the reports stop) and at once when a late wake happens (with an
inhibit time, so a burst of late wakes is one frame). A PDO rather than an SDO object: the
master reads it without a blocking request on its cycle, and a report that arrives at all
proves the producer's scheduler runs again; rather than EMCY: being late is a condition to
watch, not a device error.

Frame (8 bytes, little endian), COB-ID TPDO1 of the diagnostics node (0x180 + ID):
    0-1  late wakes since the last report       UNSIGNED16 (saturates)
    2-3  worst lateness since the last report   UNSIGNED16, 100 us (saturates at 6.5535 s)
    4-5  wakes since the last report            UNSIGNED16 (saturates)
    6    scheduling policy: 0 normal, 1 SCHED_FIFO, 2 SCHED_RR
    7    real-time priority (0 for normal)
"""
from __future__ import annotations

import os
import struct
from dataclasses import dataclass

from spacearm.base.canopen.codes import TPDO_BASE
from spacearm.base.runtime.priority import current as priority_of_thread

SIMULATOR_DIAG_NODE = 125     # node IDs below the fault-injection unit (126) and the master (127)
HUB_DIAG_NODE = 124
SIMULATOR_COB_ID = TPDO_BASE[0] + SIMULATOR_DIAG_NODE
HUB_COB_ID = TPDO_BASE[0] + HUB_DIAG_NODE
SOURCES = {SIMULATOR_COB_ID: "simulator", HUB_COB_ID: "hub"}

REPORT_PERIOD = 1.0       # s: event timer
INHIBIT_TIME = 0.1        # s: at most one event-driven report per this
LATE_WAKE = 0.005         # s past its due time: a wake that counts as late (a quarter of a 20 ms cycle)
TICK = 0.010              # s: the hub's timer tick (the simulator's scheduler wakes at least this often)

_FRAME = struct.Struct("<HHHBB")
_LSB = 1e-4               # s per unit of the lateness field
_POLICIES = {0: "normal", 1: "SCHED_FIFO", 2: "SCHED_RR"}


@dataclass(frozen=True)
class TimingReport:
    late: int
    max_lateness: float    # s
    wakes: int
    policy: str
    priority: int

    @property
    def scheduling(self) -> str:
        return self.policy if self.policy == "normal" else f"{self.policy} {self.priority}"


def decode(data: bytes) -> TimingReport | None:
    """None for a frame that is not a report (wrong length)."""
    if len(data) != _FRAME.size:
        return None
    late, lateness, wakes, policy, priority = _FRAME.unpack(data)
    return TimingReport(late, lateness * _LSB, wakes, _POLICIES.get(policy, "unknown"), priority)


def _calling_thread_scheduling() -> tuple[int, int]:
    """(policy field, priority field) of the frame for the calling thread."""
    scheduling = priority_of_thread()
    if scheduling is None:
        return 0, 0
    policy, priority = scheduling
    return {os.SCHED_FIFO: 1, os.SCHED_RR: 2}.get(policy, 0), priority


class LatenessMeter:
    """The producer's side: `woke(lateness, now)` on every timer wake; `due(now)` says when a
    report is to be sent, `report()` encodes it (call it from the timer's thread: the
    scheduling class is that thread's) and starts the next interval."""

    def __init__(self, period: float = REPORT_PERIOD, inhibit: float = INHIBIT_TIME, late_wake: float = LATE_WAKE):
        self.period, self.inhibit, self.late_wake = period, inhibit, late_wake
        self._late = self._wakes = 0
        self._worst = 0.0
        self._last_sent: float | None = None
        self._event = False

    def woke(self, lateness: float, now: float) -> None:
        self._wakes += 1
        if lateness > self.late_wake:
            self._late += 1
            self._event = True
        self._worst = max(self._worst, lateness)
        if self._last_sent is None:
            self._last_sent = now        # first report one period after start

    def next_due(self) -> float:
        """Monotonic time of the next report (event: after the inhibit time; else the event timer)."""
        if self._last_sent is None:
            return float("inf")
        return self._last_sent + (self.inhibit if self._event else self.period)

    def due(self, now: float) -> bool:
        return now >= self.next_due()

    def report(self, now: float) -> bytes:
        policy, priority = _calling_thread_scheduling()
        lateness = min(round(self._worst / _LSB), 0xFFFF)
        data = _FRAME.pack(min(self._late, 0xFFFF), lateness, min(self._wakes, 0xFFFF), policy, priority)
        self._late = self._wakes = 0
        self._worst = 0.0
        self._event = False
        self._last_sent = now
        return data
