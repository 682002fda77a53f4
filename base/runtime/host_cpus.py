"""What the host (the hypervisor under this machine) does to its vCPUs, read from /proc/stat.

On a virtual machine at its host's CPU quota the hypervisor holds one vCPU for ~100 ms now and
then (measured here: 1-3 times a minute beside two CPU-bound processes). Whatever ran on it
stands still - a simulator, the hub - however high its real-time priority, and the processes on
the other vCPU see the silence. The guest cannot see the stall as it happens in its steal count
(the held vCPU accounts its steal when it runs again), but it can see the held vCPU count no time
at all: every running or idle vCPU adds to its /proc/stat times as they pass (an idle tickless
one when read), a held one does not. A vCPU whose times stand still while another's move is being
held by the host now; a jump in its steal says it just was.
"""
from __future__ import annotations

import os

CLK_TCK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100

_stat_fd: int | None = None


def cpu_times() -> tuple[tuple[int, int], ...]:
    """(all times, steal) of each vCPU so far, in USER_HZ ticks; () where /proc cannot say. The
    file stays open, but a read costs ~0.2 ms: the kernel formats the whole file (every
    interrupt's count) for the first lines. Read it when something is amiss, not every cycle."""
    global _stat_fd
    try:
        if _stat_fd is None:
            _stat_fd = os.open("/proc/stat", os.O_RDONLY)
        head = os.pread(_stat_fd, 4096, 0).split(b"\n")
        rows = [line.split() for line in head if line[:3] == b"cpu" and line[3:4] != b" "]
        return tuple((sum(map(int, row[1:])), int(row[8])) for row in rows)
    except (OSError, ValueError, IndexError):
        return ()


def host_steal() -> tuple[int, ...]:
    """Steal of each vCPU so far (USER_HZ ticks); () where /proc cannot say."""
    return tuple(steal for _, steal in cpu_times())


def stolen_since(before: tuple[int, ...], after: tuple[int, ...]) -> float:
    """s the host held the most-stolen vCPU between two host_steal() readings."""
    return max((b - a for a, b in zip(before, after)), default=0) / CLK_TCK


class HostStallWatch:
    """Sampled once a cycle while something is amiss: is the host holding one of the vCPUs, or
    did it a moment ago? The first sample after reset() is the baseline.

    HELD: a vCPU that counted no time for this long while another did (three USER_HZ ticks:
    sampled every 20 ms, two samples after the baseline). RECENT: how long after a steal jump of
    at least HELD the stall still counts - the processes it held need a cycle to catch up."""
    HELD = 0.030      # s
    RECENT = 0.060    # s

    def __init__(self, read=cpu_times):
        self._read = read
        self._last: tuple[tuple[int, int], ...] = ()
        self._moved_at: list[float] = []
        self._stolen_at = float("-inf")
        self.held = ""              # the last sample's finding, for an event's text

    @property
    def watching(self) -> bool:
        """Sampled since the last reset (a gap under way)."""
        return bool(self._last)

    def reset(self) -> None:
        self._last = ()

    def sample(self, now: float) -> bool:
        times = self._read()
        if len(times) != len(self._last) or len(times) < 2:
            # first sample, a vCPU added or removed, or one vCPU (then a held vCPU is our own:
            # this process was late, which the cycle measures itself)
            self._last, self._moved_at = times, [now] * len(times)
            return self._just_stolen(now)
        jump = 0
        for i, ((total, steal), (was_total, was_steal)) in enumerate(zip(times, self._last)):
            if total != was_total:
                self._moved_at[i] = now
            jump = max(jump, steal - was_steal)
        self._last = times
        if jump >= self.HELD * CLK_TCK:
            self._stolen_at = now
            self.held = f"the host held a vCPU {1e3 * jump / CLK_TCK:.0f} ms (CPU steal)"
        held = [i for i, moved in enumerate(self._moved_at) if now - moved >= self.HELD]
        if held and len(held) < len(times):
            # one vCPU still while another counts: not this process's own pause (then all are)
            self.held = (f"the host is holding vCPU {held[0]} (no CPU time counted for "
                         f"{1e3 * (now - self._moved_at[held[0]]):.0f} ms)")
            return True
        return self._just_stolen(now)

    def _just_stolen(self, now: float) -> bool:
        if now - self._stolen_at <= self.RECENT:
            return True
        self.held = ""
        return False
