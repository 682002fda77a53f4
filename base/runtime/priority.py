"""Real-time scheduling for the processes on the control path (daemon, simulated nodes, hub).

On a shared machine a browser or a build takes the CPU from the control cycle just when it
wakes: with two Chromium pages open on 2 cores the daemon's period error p99 rose from
0.8 ms to 2 ms (bench/bench_web.py), and to 24 ms under extra load. SCHED_FIFO, as
ros2_control's controller manager uses, lets the cycle preempt every ordinary process.
It needs CAP_SYS_NICE (root, or an rtprio limit in /etc/security/limits.conf); without it
the process runs on as before and says why.

Call `use_fifo` before the process starts its threads: Linux threads inherit the policy of
the thread that creates them. Work that must not run at that priority (vision, the CAN
trace child) calls `use_normal` for itself.
"""
from __future__ import annotations

import os

MAX_PRIORITY = 99
# CPython hands the GIL to a waiting thread after this long (its default, 5 ms, is a quarter
# of a 20 ms cycle): the processes on the control path share the GIL between the thread that
# answers the bus and their other threads.
GIL_SWITCH_INTERVAL = 0.0005   # s


def use_fifo(priority: int) -> str | None:
    """SCHED_FIFO at `priority` (1..99) for the calling thread and the threads it starts
    later; 0 leaves the policy alone. Returns None on success, else the reason it failed."""
    if priority == 0:
        return "not requested"
    if not 1 <= priority <= MAX_PRIORITY:
        raise ValueError(f"real-time priority must be 1..{MAX_PRIORITY} (0: off), got {priority}")
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (PermissionError, OSError, AttributeError) as exc:
        return f"SCHED_FIFO not permitted ({exc}); running with normal priority"
    return None


def use_normal() -> None:
    """Back to SCHED_OTHER for the calling thread (no-op where that is already the case)."""
    try:
        if os.sched_getscheduler(0) != os.SCHED_OTHER:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (OSError, AttributeError):
        pass


def current() -> tuple[int, int] | None:
    """The calling thread's (policy, real-time priority) as os.SCHED_* and 0..99; None where
    the platform cannot say."""
    try:
        return os.sched_getscheduler(0), os.sched_getparam(0).sched_priority
    except (OSError, AttributeError):
        return None


def describe() -> str:
    """The calling thread's policy, for start-up messages."""
    scheduling = current()
    if scheduling is None:
        return "unknown"
    policy, priority = scheduling
    if policy == os.SCHED_FIFO:
        return f"SCHED_FIFO {priority}"
    return "normal"
