"""Are the nodes answering in time? The daemon's view of a starved simulator, hub or bus.

On a loaded machine a simulator or hub at normal priority answers late long before anything
fails: the TPDOs of a SYNC arrive later and later in the cycle's wait budget, heartbeats come
in bursts. The supervisor only acts once data is missing for 5 cycles or a heartbeat is 2.5
periods late; this keeps the numbers behind it over a sliding window so `status`, the console
and the web console can say "the nodes are late" while the arm still runs, and what to do.

Beside it, the simulator's and the hub's own view: each reports how late its own scheduler
woke (base/canopen/peer_timing.py, received by drivers/peer_timing.py). When they say they
were late, the message names them: the drives are not at fault, their host process is.
"""
from __future__ import annotations

from collections import deque
from dataclasses import asdict, dataclass, field

import numpy as np

WINDOW = 250           # cycles (5 s at 20 ms)
LATE_SHARE = 0.5       # of the wait budget: a SYNC answered later than this counts as late
LATE_CYCLES = 0.05     # share of late cycles in the window that makes the nodes "late"
HEARTBEAT_GAP = 1.5    # heartbeat periods between two heartbeats of one node: late
PEER_LATE = 0.020      # s: a peer that woke this late once (a whole 20 ms cycle) was late
PEER_SILENT = 3.5      # s without a report from a peer that reported before: it is not running
ADVICE = "run `spacearm sim` and `spacearm hub` with --rt-priority 50 (or lower the machine's load)"


@dataclass(frozen=True)
class PeerTimingSummary:
    """The simulator's or the hub's own report, over the reports' window."""
    level: str                    # "ok" | "late" | "silent" (reported before, nothing for PEER_SILENT)
    late_cycles: int              # its timer wakes later than peer_timing.LATE_WAKE
    cycles: int                   # its timer wakes
    max_lateness: float           # s, worst wake
    scheduling: str               # "normal" | "SCHED_FIFO 50" ...
    window: float                 # s the numbers cover
    last_report_age: float        # s
    message: str


def peer_summary(name: str, reports: list, now: float) -> PeerTimingSummary | None:
    """`reports`: [(received at, TimingReport)], oldest first; None when it never reported."""
    if not reports:
        return None
    late = sum(r.late for _, r in reports)
    wakes = sum(r.wakes for _, r in reports)
    worst = max(r.max_lateness for _, r in reports)
    scheduling = reports[-1][1].scheduling
    age = now - reports[-1][0]
    window = now - reports[0][0]
    numbers = f"{late} late of {wakes} cycles, max {1e3 * worst:.1f} ms (last {window:.0f} s, {scheduling})"
    if age > PEER_SILENT:
        level, message = "silent", f"{name} silent: no timing report for {age:.1f} s"
    elif worst >= PEER_LATE or (wakes and late > LATE_CYCLES * wakes):
        level, message = "late", f"{name} late: {numbers}"
    else:
        level, message = "ok", f"{name} on time: {numbers}"
    return PeerTimingSummary(level, late, wakes, worst, scheduling, window, age, message)


COMMANDS = {"simulator": "spacearm sim", "hub": "spacearm hub"}


def _peer_advice(name: str, peer: PeerTimingSummary) -> str:
    command = COMMANDS.get(name, name)
    if peer.level == "silent":
        return f"is `{command}` still running?"
    if peer.scheduling == "normal":
        return f"run `{command}` with --rt-priority 50 (or lower the machine's load)"
    return (f"`{command}` already runs {peer.scheduling}: something stopped it or ran above it "
            "(a debugger, SIGSTOP, a higher real-time priority)")


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
    peers: dict = field(default_factory=dict)   # "simulator"/"hub" -> PeerTimingSummary as a dict

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

    def summary(self, peer_reports: dict[str, list] | None = None, now: float = 0.0) -> NodeTimingSummary:
        """The daemon's own view, and beside it the peers' own reports (name -> reports, see
        peer_summary) as of monotonic time `now`."""
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
        peers = {name: p for name, r in (peer_reports or {}).items() if (p := peer_summary(name, r, now))}
        behind = [p.message for p in peers.values() if p.level != "ok"]
        advice = ADVICE if not behind else "; ".join(_peer_advice(n, p) for n, p in peers.items() if p.level != "ok")
        if behind:      # the host process is named first: the drives behind it are not at fault
            what = "; ".join(behind) + ("" if level == "ok" else f" (the daemon sees: {what})")
            level = "late" if level == "ok" else level
        message = what if level == "ok" else f"{what if behind else 'nodes late: ' + what}; {advice}"
        return NodeTimingSummary(level, p99, self.budget, late, missing, n, float(gap), node, message,
                                 {name: asdict(p) for name, p in peers.items()})
