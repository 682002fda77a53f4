"""Raw CAN trace (candump .log) of a bus, taken by a passive tap that sees every frame,
the controller's own included, exactly as candump would.

Receiving and formatting ~1000 frames/s in Python inside the daemon's process takes the GIL
from the control cycle (measured on 2 cores: worst cycle write 16 ms with the tap in the
daemon, 6 ms without), so on a bus another process can open (loopback hub, SocketCAN) the
tap runs as a low-priority child process. python-can's virtual bus exists
only inside one process, so there the tap stays a thread.

    python -m spacearm.controller.recording.can_trace BUS OUT.log    # what the daemon starts

The child flushes the log once per second (a kill loses at most the last second) and ends
when told (SIGTERM) or when its parent disappears.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import can

from spacearm.base.runtime.child_process import module_env, readline_within
from spacearm.base.runtime.priority import use_normal
from spacearm.base.transport import open_bus, parse_bus_spec

READY = "can_trace: ready"
FLUSH_INTERVAL = 1.0   # s
CHILD_NICENESS = 10    # the trace must never take CPU from the cycle


class CanTrace:
    """A running tap writing `path`; stop() finishes the file."""

    def __init__(self, bus_spec: str, path: Path, start_timeout: float = 10.0):
        self.path = Path(path)
        self._proc: subprocess.Popen | None = None
        self._in_process: tuple[can.BusABC, can.Notifier, can.CanutilsLogWriter] | None = None
        if parse_bus_spec(bus_spec)[0] == "virtual":
            self._in_process = _open_tap(bus_spec, self.path)
            return
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "spacearm.controller.recording.can_trace", bus_spec, str(self.path)],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=module_env(),
            preexec_fn=_below_the_cycle)
        # Wait for the tap to be on the bus so the trace covers the recording from its start.
        line = (readline_within(self._proc, start_timeout) or "").strip()
        if line != READY:
            self._proc.kill()
            self._proc.wait()
            raise RuntimeError(f"CAN trace did not start: {line or 'no answer'}")

    def stop(self, timeout: float = 5.0) -> None:
        if self._in_process is not None:
            _close_tap(*self._in_process)
            self._in_process = None
        if self._proc is not None and self._proc.poll() is None:
            self._proc.terminate()
            try:
                self._proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()


def _below_the_cycle() -> None:
    """In the child before exec: leave the daemon's real-time policy, then lower priority."""
    use_normal()
    os.nice(CHILD_NICENESS)


def _open_tap(bus_spec: str, path: Path) -> tuple[can.BusABC, can.Notifier, can.CanutilsLogWriter]:
    tap = open_bus(bus_spec)
    writer = can.CanutilsLogWriter(str(path), channel="can0", append=False)
    if hasattr(tap, "add_inline_listener"):
        # in-process bus: frames are appended in the sender's thread and formatted in batches
        # (base/transport/tap.py), not one Message, queue hop and write per frame on the cycle
        from spacearm.base.transport.tap import BufferedTap
        buffered = BufferedTap(writer, str(tap.channel_id))
        tap.add_inline_listener(buffered)
        return tap, can.Notifier(tap, [buffered], timeout=0.1), buffered
    return tap, can.Notifier(tap, [writer], timeout=0.1), writer


def _close_tap(tap: can.BusABC, notifier: can.Notifier, writer: can.CanutilsLogWriter) -> None:
    notifier.stop()
    tap.shutdown()
    writer.stop()


def main(argv: list[str] | None = None) -> int:
    bus_spec, path = argv if argv is not None else sys.argv[1:3]
    parent = os.getppid()
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    signal.signal(signal.SIGINT, lambda *_: done.set())
    try:
        tap, notifier, writer = _open_tap(bus_spec, Path(path))
    except Exception as exc:
        print(f"can_trace: cannot open {bus_spec}: {exc}", flush=True)
        return 1
    print(READY, flush=True)
    try:
        while not done.wait(FLUSH_INTERVAL) and os.getppid() == parent:
            writer.file.flush()
    finally:
        _close_tap(tap, notifier, writer)
    return 0


if __name__ == "__main__":
    sys.exit(main())
