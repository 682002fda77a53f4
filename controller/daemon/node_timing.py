"""Are the nodes answering in time? The daemon's view of a starved simulator, hub or bus.

On a loaded machine a simulator or hub at normal priority answers late long before anything
fails: the TPDOs of a SYNC arrive later and later in the cycle's wait budget, heartbeats come
in bursts. The supervisor only acts once data is missing for 5 cycles or a heartbeat is 2.5
periods late; this keeps the numbers behind it over a sliding window so `status`, the console
and the web console can say "the nodes are late" while the arm still runs, and what to do.
"""
from __future__ import annotations

from collections import deque
from dataclasses import asdict, dataclass

import numpy as np

WINDOW = 250           # cycles (5 s at 20 ms)
LATE_SHARE = 0.5       # of the wait budget: a SYNC answered later than this counts as late
LATE_CYCLES = 0.05     # share of late cycles in the window that makes the nodes "late"
HEARTBEAT_GAP = 1.5    # heartbeat periods between two heartbeats of one node: late
ADVICE = "run `spacearm sim` and `spacearm hub` with --rt-priority 50 (or lower the machine's load)"


@dataclass(frozen=True)
class NodeTimingSummary:
    level: str                    # "ok" | "late" (answers late, arm still runs) | "starved" (data missing)
    io_wait_p99: float            # s from SYNC to this SYNC's last TPDO (capped at the budget)
    budget: float                 # s the cycle waits for them
    late_cycles: int              # in the window: answered after LATE_SHARE of the budget
    missing_cycles: int           # in the window: some TPDO did not come at all
    cycles: int
    heartbeat_gap: float          # worst gap between two heartbeats of a node, in heartbeat periods
    worst_node: str
    message: str

    def as_dict(self) -> dict:
        return asdict(self)


class NodeTiming:
    def __init__(self, budget: float, window: int = WINDOW):
        self.budget = budget
        self._io_wait: deque[float] = deque(maxlen=window)
        self._missing: deque[bool] = deque(maxlen=window)
        self._gaps: deque[tuple[float, str]] = deque(maxlen=window)
        self._last_heartbeat: dict[str, float | None] = {}

    def add(self, io_wait: float, complete: bool, heartbeats: dict[str, tuple[float | None, float]]) -> None:
        """One cycle: its wait for TPDOs, whether they all came, and each node's (last heartbeat
        time, heartbeat period) as the network saw them."""
        self._io_wait.append(io_wait)
        self._missing.append(not complete)
        worst = (0.0, "")
        for name, (last, period) in heartbeats.items():
            previous = self._last_heartbeat.get(name)
            if last is not None and previous is not None and last != previous and period > 0:
                gap = (last - previous) / period
                worst = max(worst, (gap, name))
            self._last_heartbeat[name] = last
        if worst[1]:
            self._gaps.append(worst)

    def summary(self) -> NodeTimingSummary:
        n = len(self._io_wait)
        waits = np.fromiter(self._io_wait, float, n) if n else np.zeros(1)
        p99 = float(np.percentile(waits, 99))
        late = int(np.sum(waits > LATE_SHARE * self.budget)) if self.budget > 0 else 0
        missing = int(sum(self._missing))
        gap, node = max(self._gaps, default=(0.0, ""))
        if missing:
            level, what = "starved", f"{missing} of the last {n} cycles missed process data"
        elif n and (late > LATE_CYCLES * n or gap > HEARTBEAT_GAP):
            level = "late"
            what = (f"{late} of the last {n} cycles answered after {100 * LATE_SHARE:.0f} % of the "
                    f"{1e3 * self.budget:.1f} ms wait" if late > LATE_CYCLES * n
                    else f"heartbeats of {node} {gap:.1f} periods apart")
        else:
            level, what = "ok", "nodes answer in time"
        message = what if level == "ok" else f"nodes late: {what}; {ADVICE}"
        return NodeTimingSummary(level, p99, self.budget, late, missing, n, float(gap), node, message)
