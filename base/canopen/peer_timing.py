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
    6    bits 0-1 scheduling policy: 0 normal, 1 SCHED_FIFO, 2 SCHED_RR
         bits 2-4 what the worst late wake waited for: 0 none (no late wake), 1 a core,
         2 the GIL, 3 nothing ran (stopped), 4 the host (CPU steal)
    7    real-time priority (0 for normal)

What a late wake waited for, measured in the producer at each wake over the interval since the
last one (Linux schedstat of every thread of the process, /proc/self/task/*/schedstat, and the
host's steal of each vCPU, /proc/stat):
- the host: a vCPU of this machine was not run by the hypervisor (steal) for at least half of
  the lateness. Inside the guest that looks like a wait for a core or like nothing running, so
  it is asked first: on a machine at its host CPU quota every process on the vCPU, at any
  real-time priority, stands still ~100 ms. The guest counts steal once its vCPU runs again, so
  a late wake's report waits STEAL_SETTLE before it is judged and sent;
- a core: the timer thread itself was runnable but not running (run-queue delay) for at least
  half of its lateness - other processes (or higher real-time priorities) had the cores;
- the GIL: the process's other threads ran or waited to run for at least half of it - one of
  them held the GIL the timer thread needed (a preempted holder counts: it waits for a core
  while holding it, the priority inversion bench/bench_realtime.py measures);
- stopped: none of these - no thread of the process ran or was waiting to run: SIGSTOP, a
  debugger, or a host stall the steal count did not show (it counts in 10 ms ticks). A stopped
  wake with any steal counted around it is the host's: at load 15 beside other real-time
  processes (bench_realtime idle), a FIFO 50 hub's one 22.9 ms wake with no run-queue delay and
  no GIL wait was called stopped, and the banner blamed a debugger for 10 minutes.
"""
from __future__ import annotations

import os
import struct
import threading
import time
from dataclasses import dataclass

from spacearm.base.canopen.codes import TPDO_BASE
from spacearm.base.runtime.host_cpus import host_steal, stolen_since
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
CAUSES = ("", "core", "gil", "stopped", "host")   # what the worst late wake waited for ("": no late wake)
# /proc/stat costs ~0.2 ms a read (the kernel formats all of it): every 10th wake (~100 ms) is
# the baseline a late wake's steal is measured from; a 100 ms stall still covers half its lateness
STEAL_READ_EVERY = 10
STEAL_SETTLE = 0.03       # s after a late wake before its report: the guest's steal count catches up


@dataclass(frozen=True)
class TimingReport:
    late: int
    max_lateness: float    # s
    wakes: int
    policy: str
    priority: int
    cause: str = ""        # CAUSES: what its worst late wake waited for

    @property
    def scheduling(self) -> str:
        return self.policy if self.policy == "normal" else f"{self.policy} {self.priority}"


def decode(data: bytes) -> TimingReport | None:
    """None for a frame that is not a report (wrong length)."""
    if len(data) != _FRAME.size:
        return None
    late, lateness, wakes, flags, priority = _FRAME.unpack(data)
    return TimingReport(late, lateness * _LSB, wakes, _POLICIES.get(flags & 3, "unknown"), priority,
                        CAUSES[(flags >> 2) & 7] if (flags >> 2) & 7 < len(CAUSES) else "")


def _calling_thread_scheduling() -> tuple[int, int]:
    """(policy field, priority field) of the frame for the calling thread."""
    scheduling = priority_of_thread()
    if scheduling is None:
        return 0, 0
    policy, priority = scheduling
    return {os.SCHED_FIFO: 1, os.SCHED_RR: 2}.get(policy, 0), priority


_task_files: dict[str, int] = {}     # thread ID -> open descriptor of its schedstat (read with pread)
_task_links = -1                     # /proc/self/task's link count at the last listing (2 + threads)
_task_reads = 0                      # _task_times calls since that listing
# list again at least this often, where the link count does not follow the threads (not Linux's procfs)
TASKS_RELIST_EVERY = 64
_task_lock = threading.Lock()


def _forget_task_files() -> None:
    global _task_links
    for fd in _task_files.values():
        try:
            os.close(fd)
        except OSError:
            pass
    _task_files.clear()
    _task_links = -1


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_task_files)    # a child's threads are others


def _sum_tasks(own_tid: str, listed_now: bool) -> tuple[int, int, int | None] | None:
    """(CPU ns, run-queue ns) over the threads listed, and the calling thread's run-queue ns
    (None: not among them). A thread that has ended (ESRCH): None, to list them again, unless
    they were listed just now; then it is left out, as it is gone."""
    cpu = queue = 0
    own = None
    ended = []
    for tid, fd in _task_files.items():
        try:
            fields = os.pread(fd, 128, 0).split()
            c, q = int(fields[0]), int(fields[1])
        except (OSError, ValueError, IndexError):
            if not listed_now:
                return None
            ended.append(tid)
            continue
        cpu += c
        queue += q
        if tid == own_tid:
            own = q
    for tid in ended:
        os.close(_task_files.pop(tid))
    return cpu, queue, own


def _list_tasks() -> None:
    """Open the schedstat of every thread of the process now, close those of ended ones."""
    tids = os.listdir("/proc/self/task")
    for tid in set(_task_files) - set(tids):
        os.close(_task_files.pop(tid))
    for tid in tids:
        if tid not in _task_files:
            try:
                _task_files[tid] = os.open(f"/proc/self/task/{tid}/schedstat", os.O_RDONLY)
            except OSError:       # a thread that ended meanwhile
                pass


def _task_times() -> tuple[int, int, int]:
    """(CPU ns, run-queue ns) summed over this process's threads, and the calling thread's
    run-queue ns; zeros where /proc cannot say. Each thread's file stays open (one pread per
    thread and wake, not open/read/close): the cost of a pass grows with the process's
    threads, and the simulator's timer pays it on every wake. The threads are listed again only
    when their number changed (the task folder's link count: one stat), one has ended (its
    read fails: one ended and another started between two wakes) or the calling thread is new;
    listing the folder and opening the calling thread's own file on every wake were most of
    the cost of a wake (issue 35)."""
    global _task_links, _task_reads
    own_tid = str(threading.get_native_id())
    try:
        with _task_lock:
            links = os.stat("/proc/self/task").st_nlink
            _task_reads += 1
            times = None
            if links == _task_links and _task_reads < TASKS_RELIST_EVERY:
                times = _sum_tasks(own_tid, listed_now=False)
            if times is None or times[2] is None:
                _list_tasks()
                _task_links, _task_reads = links, 0
                times = _sum_tasks(own_tid, listed_now=True)
    except (OSError, ValueError, IndexError):
        return 0, 0, 0
    cpu, queue, own = times
    return (cpu, queue, own) if own is not None else (0, 0, 0)


def wake_cause(lateness: float, own_queue: float, own_cpu: float, all_busy: float) -> str:
    """What a late wake waited for inside the guest (module doc): own_queue s runnable without a
    core, own_cpu s it ran, all_busy s the whole process ran or waited for a core, over the same
    interval. The host's part is judged at the report (LatenessMeter.report), once counted."""
    if own_queue >= lateness / 2:
        return "core"
    if all_busy - own_queue - own_cpu >= lateness / 2:
        return "gil"
    return "stopped"


class LatenessMeter:
    """The producer's side: `woke(lateness, now)` on every timer wake; `due(now)` says when a
    report is to be sent, `report()` encodes it (call it from the timer's thread: the
    scheduling class is that thread's) and starts the next interval."""

    def __init__(self, period: float = REPORT_PERIOD, inhibit: float = INHIBIT_TIME, late_wake: float = LATE_WAKE,
                 measure_causes: bool = True):
        self.period, self.inhibit, self.late_wake = period, inhibit, late_wake
        self._late = self._wakes = 0
        self._worst = 0.0
        self._worst_cause = ""
        # (process CPU + run-queue ns, own run-queue ns, own CPU s) at the last wake
        self._times: tuple[int, int, float] | None = None
        self._steal: tuple[int, ...] = ()          # host_steal() at a recent wake (STEAL_READ_EVERY)
        self._worst_steal: tuple[int, ...] = ()    # ... before the worst late wake
        self._worst_at = float("-inf")
        self.measure_causes = measure_causes
        self._last_sent: float | None = None
        self._event = False

    def woke(self, lateness: float, now: float) -> str:
        """Call from the timer's thread (its schedstat is the one read); returns what this wake
        waited for ("" when it was on time)."""
        self._wakes += 1
        cause = self._cause(lateness) if self.measure_causes else ""
        if lateness > self.late_wake:
            self._late += 1
            self._event = True
        steal_before = self._steal
        if self.measure_causes and self._wakes % STEAL_READ_EVERY == 1:
            self._steal = host_steal()
        if lateness > self._worst:
            self._worst = lateness
            self._worst_cause = cause if lateness > self.late_wake else ""
            self._worst_steal, self._worst_at = steal_before, now
        if self._last_sent is None:
            self._last_sent = now        # first report one period after start
        return cause

    def _cause(self, lateness: float) -> str:
        """What this wake waited for, from the times since the last wake ("" on the first)."""
        cpu, queue, own_queue = _task_times()
        own_cpu = time.thread_time()
        last, self._times = self._times, (cpu + queue, own_queue, own_cpu)
        if last is None or lateness <= self.late_wake:
            return ""
        return wake_cause(lateness, (own_queue - last[1]) * 1e-9, own_cpu - last[2], (cpu + queue - last[0]) * 1e-9)

    def next_due(self) -> float:
        """Monotonic time of the next report (event: after the inhibit time; else the event timer)."""
        if self._last_sent is None:
            return float("inf")
        if self._event:
            return max(self._last_sent + self.inhibit, self._worst_at + STEAL_SETTLE)
        return self._last_sent + self.period

    def due(self, now: float) -> bool:
        return now >= self.next_due()

    def report(self, now: float) -> bytes:
        policy, priority = _calling_thread_scheduling()
        if self._worst_cause and self._worst_steal:
            stolen = stolen_since(self._worst_steal, host_steal())
            # steal is counted in 10 ms ticks: a wake that nothing in the guest explains
            # ("stopped") with any steal around it is the host's, not a debugger's
            if stolen >= self._worst / 2 or (stolen > 0 and self._worst_cause == "stopped"):
                self._worst_cause = "host"
        lateness = min(round(self._worst / _LSB), 0xFFFF)
        flags = policy | CAUSES.index(self._worst_cause) << 2
        data = _FRAME.pack(min(self._late, 0xFFFF), lateness, min(self._wakes, 0xFFFF), flags, priority)
        self._late = self._wakes = 0
        self._worst = 0.0
        self._worst_cause = ""
        self._worst_steal, self._worst_at = (), float("-inf")
        self._event = False
        self._last_sent = now
        return data
