"""What the HIL tests and the benchmarks that drive the same process stacks share."""
from __future__ import annotations

import os
import socket

CHROMIUM = os.environ.get("SPACEARM_CHROMIUM", "/usr/bin/chromium")
# No GPU here: WebGL on SwiftShader, but the page itself rastered and composited by Skia on
# the CPU (rastering it through SwiftShader costs about 3x the CPU, measured).
CHROMIUM_ARGS = ["--use-gl=angle", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                 "--ignore-gpu-blocklist", "--disable-gpu-rasterization", "--disable-gpu-compositing"]


def patient_bus(out):
    """The arm's bus with slower heartbeats (loss after 1 s instead of 0.25 s), written to `out`:
    on a loaded 2-core machine a busy process (a camera render, a diagnosis) can starve the
    nodes' heartbeat threads for a few hundred ms. For tests where supervision is not under test."""
    from pathlib import Path
    root = Path(__file__).resolve().parents[1]
    text = (root / "configs/bus/arm.toml").read_text().replace("heartbeat_period = 0.1", "heartbeat_period = 0.4")
    text = text.replace("[bus]\n", "[bus]\nmaster_heartbeat_timeout = 1.5\nlockstep_timeout = 2.0\n", 1)
    out.write_text(text)
    return out


def free_port() -> int:
    """A TCP port on the loopback interface that nothing listens on right now."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


class CpuSteal:
    """Share of this machine's CPU time the hypervisor gave to other guests (the `st` column
    of vmstat) since the last reading: on a VM, the vCPUs can stall for milliseconds no
    matter what runs inside, and the benchmarks print it next to overruns."""

    def __init__(self):
        self._last = self._read()

    @staticmethod
    def _read() -> tuple[int, int]:
        with open("/proc/stat") as handle:
            fields = [int(v) for v in handle.readline().split()[1:9]]
        return fields[7], sum(fields)          # steal, total (user .. steal)

    def fraction(self) -> float:
        steal, total = self._read()
        d_steal, d_total = steal - self._last[0], total - self._last[1]
        self._last = (steal, total)
        return d_steal / d_total if d_total > 0 else 0.0


class StealTimeline:
    """Per-CPU steal over time (a thread at SCHED_FIFO 1 reads /proc/stat every `interval` s),
    to ask afterwards how long the hypervisor held one vCPU within a window: a host that takes
    a vCPU for ~100 ms (its CPU quota's period, on a machine at its quota) stalls every process
    on it, a simulator or a hub at SCHED_FIFO 99 alike, and the controller on the other vCPU
    rightly sees its nodes silent."""

    def __init__(self, interval: float = 0.01):
        import threading
        import time
        self._samples: list[tuple[float, list[int]]] = []
        self._stop = threading.Event()

        def sample():
            from spacearm.base.runtime.priority import use_fifo
            use_fifo(1)         # read on time beside CPU-bound neighbours (it sleeps almost always)
            while not self._stop.wait(interval):
                self._samples.append((time.monotonic(), self._read()))
        self._thread = threading.Thread(target=sample, name="steal-timeline", daemon=True)
        self._thread.start()

    @staticmethod
    def _read() -> list[int]:
        with open("/proc/stat") as handle:
            return [int(line.split()[8]) for line in handle if line.startswith("cpu") and line[3] != " "]

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(1.0)

    def worst_cpu(self, start: float, end: float) -> float:
        """s of steal of the most-stolen vCPU between the last sample before `start` and the
        first after `end` (USER_HZ ticks: 10 ms resolution)."""
        samples = list(self._samples)
        # a window reaching before the first sample (or past the last) starts (ends) there
        before = [s for t, s in samples if t <= start][-1:] or [s for _, s in samples[:1]]
        after = [s for t, s in samples if t >= end][:1] or [s for _, s in samples[-1:]]
        if not before or not after:
            return 0.0
        return max((b - a for a, b in zip(before[0], after[0])), default=0) / os.sysconf("SC_CLK_TCK")


def host_stall_around_stop(status: dict, steal: StealTimeline) -> tuple[float, float] | None:
    """(s of steal of the most-stolen vCPU, s of the window) around a stop for missing data or a
    lost heartbeat; None for any other stop, or none. The stall that silenced the nodes for the
    stop's reach may still be on at the stop, and the guest counts steal when its vCPU runs
    again: the window reaches past the stop too."""
    stop = status.get("stop") or {}
    if stop.get("code") not in ("pdo_missing", "heartbeat_lost"):
        return None
    at = [e["t"] for e in status.get("events", ()) if e.get("kind") == "protective_stop"]
    if not at:
        return None
    stopped = status["woke_at"] - (status["time"] - at[-1])      # the stop's cycle, monotonic
    before, after = 0.1 + 2 * status["period"], 0.12
    return steal.worst_cpu(stopped - before, stopped + after), before + after


def xfail_if_the_host_stalled_a_vcpu(status: dict, steal: StealTimeline, peers: dict | None = None) -> None:
    """A stop for missing data or a lost heartbeat while the hypervisor held a vCPU for most of
    the stop's reach (5 cycles: 100 ms) just before it is the machine's, not the stack's: every
    process on that vCPU (the simulator, the hub, at any real-time priority) stood still, and
    the daemon on the other one rightly saw its nodes silent. Reported as such (xfail with the
    measured steal and the peers' own reports), not as a pass, and not as a fault of the stack.
    Traced on the hub (issue 32): such stops came with ~100 ms without a forwarded frame, ending
    within 1 ms of a pinned SCHED_FIFO 99 probe's 100 ms late wake on one vCPU, and 100 ms of
    steal on that vCPU (the host's CPU quota period)."""
    stall = host_stall_around_stop(status, steal)
    if stall is not None and stall[0] >= HOST_STALL:
        import pytest
        stolen, window = stall
        peers = peers if peers is not None else (status.get("nodes") or {}).get("peers") or {}
        reports = ", ".join(f"{name} {1e3 * p['max_lateness']:.0f} ms ({p.get('cause') or '-'})"
                            for name, p in peers.items()) or "-"
        pytest.xfail(f"{status['stop']['code']} while the host held one vCPU for {1e3 * stolen:.0f} ms of the "
                     f"{1e3 * window:.0f} ms around it (CPU steal); peers' worst wakes: {reports}")


# s of steal on one vCPU within the stop's reach that stalls the processes on it for most of it
HOST_STALL = 0.06


def stop_group(proc) -> None:
    """End a process started with start_new_session=True and everything it started: SIGTERM to
    its group, SIGKILL after 10 s."""
    import os
    import signal
    import subprocess
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(5)
