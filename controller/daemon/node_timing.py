"""Are the nodes answering in time? The daemon's view of a starved simulator, hub or bus.

On a loaded machine a simulator or hub at normal priority answers late long before anything
fails: the TPDOs of a SYNC arrive later and later in the cycle's wait budget, heartbeats come
in bursts. The supervisor only acts once data is missing for 5 cycles or a heartbeat is 2.5
periods late; this keeps the numbers behind it over a sliding window so `status`, the console
and the web console can say "the nodes are late" while the arm still runs, and what to do.

Beside it, the simulator's and the hub's own view: each reports how late its own scheduler
woke and what its worst late wake waited for - a core, the GIL, or nothing ran at all
(base/canopen/peer_timing.py, received by drivers/peer_timing.py). When they say they were
late, the message names them and that cause: the drives are not at fault, their host process
is, and the advice fits the cause (never --rt-priority to a process already at SCHED_FIFO).

Hysteresis: on a loaded machine a process at SCHED_FIFO still sees a single wake tens of ms
late now and then (the host: bench/bench_realtime.py gil, "none" row), and an idle arm must not
show a banner for it. A peer is late only for what could stop the arm or keeps recurring: one
wake PEER_SERIOUS late, PEER_LATE_REPORTS reports in its window with a wake PEER_LATE late, or
late wakes in more than LATE_CYCLES of its cycles; once late it stays so while any such report
is in the window. The daemon's own heartbeat view likewise: one gap of HEARTBEAT_SERIOUS
periods, or HEARTBEAT_GAPS gaps over HEARTBEAT_GAP in its window. Missing data: one cycle
alone is said, MISSING_RUN in a row or MISSING_CYCLES in the window are "starved".

The host is not a node: on a virtual machine at its host's CPU quota the hypervisor holds a vCPU
for ~100 ms now and then (base/runtime/host_cpus.py), and whatever ran on it stands still. Data
missing while the daemon saw a vCPU held, and a peer's late wake it measured as the host's, are
said (the count and the cause) but are not "the nodes are late": no setting of this stack
changes them, and an idle arm on such a machine would show a banner every few seconds.

Lockstep: the cycle waits for every answer and the nodes keep SYNC time, so wall-clock
heartbeat gaps follow the machine's speed, not the nodes (a lockstep run through a bus line
cut said "heartbeats of joint_6 10.3 periods apart; run `spacearm sim` ... --rt-priority 50"
of an in-process simulator). There only missing data is judged, and no scheduling advice given.
"""
from __future__ import annotations

from collections import deque
from dataclasses import asdict, dataclass, field

import numpy as np

from spacearm.base.canopen.peer_timing import LATE_WAKE

WINDOW = 250           # cycles (5 s at 20 ms)
# A cycle is late when its data came after the TPDO wait, later in its period: the cycle ran
# on the previous data. An answer inside the wait is on time however far into it: a simulator
# computing its physics answers 4-7 ms into the 8 ms wait on a loaded machine (the ORU cell's
# contact world), and nothing the arm does depends on when within the wait it came.
LATE_CYCLES = 0.05     # share of late cycles in the window that makes the nodes "late"
HEARTBEAT_GAP = 1.5    # heartbeat periods between two heartbeats of one node: late ...
HEARTBEAT_GAPS = 3     # ... when it happens this often in the window
HEARTBEAT_SERIOUS = 2.0   # periods: once is enough (the stop comes at 2.5)
MISSING_CYCLES = 3     # cycles without all process data in the window: "starved" ...
MISSING_RUN = 2        # ... or this many in a row (one alone, on a loaded machine, is said, not a banner)
STALL_GAP_CYCLES = 15  # a heartbeat gap ending this soon after a host stall or a late cycle is theirs
HOST_GAP_SLACK = 0.010  # s: a heartbeat this much later than a peer's host-held wake is still the host's
PEER_LATE = 0.020      # s: a wake this late (a whole 20 ms cycle) ...
PEER_LATE_REPORTS = 3  # ... in this many of a peer's reports in its window makes it late
PEER_SERIOUS = 0.100   # s: once is enough (5 cycles: the missing-data stop's reach)
PEER_SILENT = 3.5      # s without a report from a peer that reported before: it is not running
# neither peer has reported its scheduling (none yet, or an older one): the advice cannot know it
ADVICE = ("no timing report from `spacearm sim` or `spacearm hub`: if they run at normal priority, start "
          "them with --rt-priority 50; otherwise lower the machine's load")
CAUSE_TEXT = {"core": "waited for a core", "gil": "waited for the GIL (another of its threads held it)",
              "stopped": "stopped (none of its threads ran)",
              "host": "the host did not run its vCPU (CPU steal)"}


@dataclass(frozen=True)
class PeerTimingSummary:
    """The simulator's or the hub's own report, over the reports' window."""
    level: str                    # "ok" | "late" | "silent" (reported before, nothing for PEER_SILENT)
    late_cycles: int              # its timer wakes later than peer_timing.LATE_WAKE
    cycles: int                   # its timer wakes
    max_lateness: float           # s, worst wake
    cause: str                    # what its worst late wake waited for: "core" | "gil" | "stopped" | "host" | ""
    scheduling: str               # "normal" | "SCHED_FIFO 50" ...
    window: float                 # s the numbers cover
    last_report_age: float        # s
    message: str


def longest_run(flags: list[bool]) -> int:
    longest = current = 0
    for flag in flags:
        current = current + 1 if flag else 0
        longest = max(longest, current)
    return longest


def peer_summary(name: str, reports: list, now: float, was_late: bool = False) -> PeerTimingSummary | None:
    """`reports`: [(received at, TimingReport)], oldest first; None when it never reported.
    was_late: it was late at the last summary (hysteresis, module doc)."""
    if not reports:
        return None
    late = sum(r.late for _, r in reports)
    wakes = sum(r.wakes for _, r in reports)
    worst_at, worst = max(((r.max_lateness, r) for _, r in reports), key=lambda w: w[0])
    scheduling = reports[-1][1].scheduling
    age = now - reports[-1][0]
    window = now - reports[0][0]
    # a report whose worst wake the host caused is not the peer's lateness (module doc)
    own = [r for _, r in reports if r.cause != "host"]
    bad = sum(r.max_lateness >= PEER_LATE for r in own)
    own_worst = max((r.max_lateness for r in own), default=0.0)
    cause = worst.cause if worst_at > LATE_WAKE else ""
    numbers = (f"{late} late of {wakes} cycles, max {1e3 * worst_at:.1f} ms"
               + (f", {CAUSE_TEXT[cause]}" if cause else "") + f" (last {window:.0f} s, {scheduling})")
    if age > PEER_SILENT:
        level, message = "silent", f"{name} silent: no timing report for {age:.1f} s"
    elif (own_worst >= PEER_SERIOUS or bad >= PEER_LATE_REPORTS or (wakes and late > LATE_CYCLES * wakes)
          or (was_late and bad)):
        level, message = "late", f"{name} late: {numbers}"
    elif own_worst < worst_at:
        level, message = "ok", f"{name} on time but for the host: {numbers}"
    else:
        level, message = "ok", f"{name} on time: {numbers}"
    return PeerTimingSummary(level, late, wakes, worst_at, cause, scheduling, window, age, message)


COMMANDS = {"simulator": "spacearm sim", "hub": "spacearm hub"}


def _peer_advice(name: str, peer: PeerTimingSummary) -> str:
    command = COMMANDS.get(name, name)
    if peer.level == "silent":
        return f"is `{command}` still running?"
    if peer.cause == "gil":
        return (f"a thread of `{command}` below its real-time priority held the GIL (it must run at the "
                "nodes' priority or in its own process)")
    if peer.cause == "host":
        return ("the machine's host did not run it (CPU steal, ~100 ms at the host's CPU quota): no priority "
                "helps; a machine with reserved CPUs does")
    if peer.cause == "stopped":
        return (f"`{command}` did not run at all and did not wait for a core: a debugger or SIGSTOP, or the "
                "host holding its vCPU for less than the 10 ms that CPU steal is counted in")
    if peer.scheduling == "normal":
        return f"run `{command}` with --rt-priority 50 (or lower the machine's load)"
    if peer.cause == "core":
        return f"`{command}` already runs {peer.scheduling}: a process at a higher real-time priority took its core"
    return (f"`{command}` already runs {peer.scheduling}: something stopped it or ran above it "
            "(a debugger, SIGSTOP, a higher real-time priority)")


@dataclass(frozen=True)
class NodeTimingSummary:
    level: str                    # "ok" | "late" (answers late, arm still runs) | "starved" (data missing)
    io_wait_p99: float            # s from SYNC to this SYNC's last TPDO (capped at the budget)
    budget: float                 # s the cycle waits for them
    late_cycles: int              # in the window: data came after the wait (in its period)
    missing_cycles: int           # in the window: some TPDO did not come at all (the host not holding a vCPU)
    cycles: int
    heartbeat_gap: float          # worst gap between two heartbeats of a node, in heartbeat periods
    worst_node: str
    message: str
    peers: dict = field(default_factory=dict)   # "simulator"/"hub" -> PeerTimingSummary as a dict
    host_stalled_cycles: int = 0  # in the window: data missing while the host held a vCPU

    def as_dict(self) -> dict:
        return asdict(self)


class NodeTiming:
    def __init__(self, budget: float, window: int = WINDOW, lockstep: bool = False):
        self.budget = budget
        self.lockstep = lockstep
        self._io_wait: deque[float] = deque(maxlen=window)
        self._missing: deque[bool] = deque(maxlen=window)
        self._late: deque[bool] = deque(maxlen=window)
        self._host_stalled: deque[bool] = deque(maxlen=window)
        self._bridged: deque[bool] = deque(maxlen=window)
        self._gaps: deque[tuple[float, str, float]] = deque(maxlen=window)   # periods, node, s late
        self._last_heartbeat: dict[str, float | None] = {}
        self._peer_late: dict[str, bool] = {}
        self._since_stall = STALL_GAP_CYCLES     # cycles since the host or this process last stalled

    def add(self, io_wait: float, complete: bool, heartbeats: dict[str, tuple[float | None, float]],
            host_stalled: bool = False, last_answered_late: bool = False, starved: bool = False,
            bridged: bool = False) -> None:
        """One cycle: its wait for TPDOs, whether they all came, and each node's (last heartbeat
        time, heartbeat period) as the network saw them. host_stalled: the host held a vCPU in
        this cycle's gap (the gap's missing cycles are the host's). last_answered_late: every node
        missing at the last cycle's read sent its data later in that period - that cycle was
        late, not missing data. starved: this process itself ran late (skipped cycles): the
        heartbeats it received meanwhile arrived late. bridged: a bus line switch was under way
        (drivers/line_redundancy.py): its missing data and heartbeat gaps are the cut line's."""
        if last_answered_late and self._missing and self._missing[-1]:
            self._missing[-1], self._late[-1] = False, True
        k = len(self._missing)
        while host_stalled and k and self._missing[k - 1]:
            # the gap's first cycles, before the held vCPU showed (HostStallWatch.HELD): the host's too
            k -= 1
            self._missing[k], self._host_stalled[k] = False, True
        self._io_wait.append(io_wait)
        self._missing.append(not complete and not host_stalled and not bridged)
        self._late.append(False)
        self._host_stalled.append(host_stalled and not complete)
        self._bridged.append(bridged and not complete)
        self._since_stall = 0 if host_stalled or starved or bridged else self._since_stall + 1
        worst = (0.0, "", 0.0)
        for name, (last, period) in heartbeats.items() if not self.lockstep else ():
            previous = self._last_heartbeat.get(name)
            if last is not None and previous is not None and last != previous and period > 0:
                gap = (last - previous) / period
                worst = max(worst, (gap, name, last - previous - period))
            self._last_heartbeat[name] = last
        if worst[1] and self._since_stall >= STALL_GAP_CYCLES:   # else the stall's gap, not the node's
            self._gaps.append(worst)

    def summary(self, peer_reports: dict[str, list] | None = None, now: float = 0.0) -> NodeTimingSummary:
        """The daemon's own view, and beside it the peers' own reports (name -> reports, see
        peer_summary) as of monotonic time `now`."""
        # copies first: the cycle thread appends while an API thread asks (a deque mutated
        # during iteration raised in `status` polled every 10 ms); list() copies under the GIL
        io_wait, missing_cycles, heartbeat_gaps = list(self._io_wait), list(self._missing), list(self._gaps)
        peers = {name: p for name, r in (peer_reports or {}).items()
                 if (p := peer_summary(name, r, now, self._peer_late.get(name, False)))}
        # a peer whose timer the host held (its own report) sent its heartbeats late by as much:
        # gaps no longer than that are the host's (its SYNC answers may have come from a thread
        # on the other vCPU, so no data went missing for the daemon to see the stall)
        host_held = max((p.max_lateness for p in peers.values() if p.cause == "host"), default=-1.0)
        heartbeat_gaps = [(g, name) for g, name, late in heartbeat_gaps if late > host_held + HOST_GAP_SLACK]
        host_stalled = sum(list(self._host_stalled))
        n = len(io_wait)
        waits = np.array(io_wait, float) if n else np.zeros(1)
        p99 = float(np.percentile(waits, 99))
        late = sum(list(self._late))
        missing = int(sum(missing_cycles))
        run = longest_run(missing_cycles)
        gap, node = max(heartbeat_gaps, default=(0.0, ""))
        gaps = sum(g > HEARTBEAT_GAP for g, _ in heartbeat_gaps)
        if missing >= MISSING_CYCLES or run >= MISSING_RUN:
            level, what = "starved", f"{missing} of the last {n} cycles missed process data"
        elif n and late > LATE_CYCLES * max(n, self._io_wait.maxlen or n):
            # a share of the whole window, also while it fills: one late cycle in a window of three
            # is not 5 % of anything (bench_realtime idle, load 2.5: 'the data of 1 of the last 3
            # cycles came after the 8.0 ms wait' was an idle arm's only banner in 10 minutes)
            level = "late"
            what = (f"the data of {late} of the last {n} cycles came after the {1e3 * self.budget:.1f} ms "
                    "wait (those cycles ran on the previous data)")
        elif gap >= HEARTBEAT_SERIOUS or gaps >= HEARTBEAT_GAPS:
            level, what = "late", f"heartbeats of {node} {gap:.1f} periods apart"
        else:
            level, what = "ok", "nodes answer in time" + (
                f"; {missing} of the last {n} cycles missed process data" if missing else "")
        if host_stalled:
            what += (f"; the host held a vCPU in {host_stalled} of the last {n} cycles (CPU steal): their "
                     "missing data is the host's, not the nodes'")
        if bridged := sum(list(self._bridged)):
            what += f"; {bridged} of the last {n} cycles bridged a bus line switch (their data was on the cut line)"
        self._peer_late = {name: p.level == "late" for name, p in peers.items()}
        behind = [p.message for p in peers.values() if p.level != "ok"]
        if behind:
            advice = "; ".join(_peer_advice(n, p) for n, p in peers.items() if p.level != "ok")
        elif peers and all(p.scheduling != "normal" for p in peers.values()):
            # they run real time and say they were on time: the delay is not theirs to fix
            advice = (f"the {' and the '.join(peers)} report{'s' if len(peers) == 1 else ''} on time at "
                      f"{'/'.join(sorted({p.scheduling for p in peers.values()}))}: look at the bus or this daemon's load")
        elif self.lockstep:
            advice = "in lockstep the cycle waited for them: the bus or the nodes, not scheduling"
        else:
            advice = ADVICE
        if behind:      # the host process is named first: the drives behind it are not at fault
            what = "; ".join(behind) + ("" if level == "ok" else f" (the daemon sees: {what})")
            level = "late" if level == "ok" else level
        message = what if level == "ok" else f"{what if behind else 'nodes late: ' + what}; {advice}"
        return NodeTimingSummary(level, p99, self.budget, late, missing, n, float(gap), node, message,
                                 {name: asdict(p) for name, p in peers.items()}, host_stalled)
