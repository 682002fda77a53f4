"""Raw CAN trace (candump .log) of a bus, taken by a passive tap that sees every frame,
the controller's own included, exactly as candump would.

Receiving and formatting ~1000 frames/s in Python inside the daemon's process takes the GIL
from the control cycle (measured on 2 cores: worst cycle write 16 ms with the tap in the
daemon, 6 ms without), so on a bus another process can open (loopback hub, SocketCAN) the
tap runs as a child process, lowered to niceness 10 once it is on the bus. python-can's virtual bus exists
only inside one process, so there the tap is an inline listener that only collects frames; a
child formats them in batches (trace_stream.py). On a redundant pair the tap hears
both lines and each frame's channel column is its line's name (`arm-a`, `vcan1`;
base/transport/redundant.py `line_channel`), as `candump -l any` writes it.

    python -m spacearm.controller.recording.can_trace BUS OUT.log [MAX_BYTES KEEP]   # what the daemon starts

The child flushes the log once per second (a kill loses at most the last second) and ends
when told (SIGTERM) or when its parent disappears. The trace grows ~320 MB/h at 50 Hz, so it is
rotated like logging's RotatingFileHandler: past `max_bytes` the file becomes `.1` (older ones
shift to `.2`, ...), and only `keep` rotated files stay (TraceLimit; `spacearm daemon
--can-trace-max-mb/--can-trace-files`).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from dataclasses import dataclass
from pathlib import Path

import can

from spacearm.base.runtime.child_process import module_env, readline_within
from spacearm.base.runtime.priority import use_normal
from spacearm.base.transport import open_bus, parse_bus_spec
from spacearm.controller.recording.trace_stream import StreamTap

READY = "can_trace: ready"
FLUSH_INTERVAL = 1.0   # s
CHILD_NICENESS = 10    # the trace must never take CPU from the cycle
SIZE_CHECK_FRAMES = 256   # look at the file size every this many frames (cheap, bounded overshoot)


@dataclass(frozen=True)
class TraceLimit:
    max_bytes: int = 64 * 1024 * 1024   # per file; 0: no limit (one file, never rotated)
    keep: int = 4                       # rotated files kept beside the current one

    def __post_init__(self) -> None:
        if self.max_bytes < 0 or self.keep < 0:
            raise ValueError(f"CAN trace limit must be >= 0, got {self.max_bytes} bytes, {self.keep} files")


class RotatingTraceWriter(can.Listener):
    """candump .log writer that rotates at `limit.max_bytes` and keeps `limit.keep` old files."""

    def __init__(self, path: Path, limit: TraceLimit):
        self.path, self.limit = Path(path), limit
        self._lock = threading.Lock()
        self._frames = 0
        self.rotations = 0
        self._writer = can.CanutilsLogWriter(str(self.path), channel="can0", append=False)

    @property
    def file(self):
        return self._writer.file

    @property
    def last_timestamp(self) -> float | None:      # for the in-process tap's batch formatting
        return self._writer.last_timestamp

    @last_timestamp.setter
    def last_timestamp(self, value: float | None) -> None:
        self._writer.last_timestamp = value

    def rotate_if_full(self) -> None:
        """After a batch written straight to `file` (the in-process tap)."""
        with self._lock:
            if self.limit.max_bytes and self._writer.file.tell() >= self.limit.max_bytes:
                self._rotate()

    def on_message_received(self, msg: can.Message) -> None:
        with self._lock:
            self._writer.on_message_received(msg)
            self._frames += 1
            if self.limit.max_bytes and self._frames % SIZE_CHECK_FRAMES == 0 \
                    and self._writer.file.tell() >= self.limit.max_bytes:
                self._rotate()

    def _rotate(self) -> None:
        self._writer.stop()
        rotated = [self.path.with_name(f"{self.path.name}.{i}") for i in range(1, self.limit.keep + 1)]
        if rotated:
            rotated[-1].unlink(missing_ok=True)
            for older, newer in zip(reversed(rotated[1:]), reversed(rotated[:-1])):
                if newer.exists():
                    newer.rename(older)
            self.path.rename(rotated[0])
        self._writer = can.CanutilsLogWriter(str(self.path), channel="can0", append=False)
        self.rotations += 1

    def flush(self) -> None:
        with self._lock:
            self._writer.file.flush()

    def stop(self) -> None:
        with self._lock:
            self._writer.stop()


class CanTrace:
    """A running tap writing `path`; stop() finishes the file."""

    def __init__(self, bus_spec: str, path: Path, start_timeout: float = 10.0, limit: TraceLimit = TraceLimit()):
        self.path = Path(path)
        self._proc: subprocess.Popen | None = None
        self._in_process: tuple[can.BusABC, can.Notifier, RotatingTraceWriter] | None = None
        if parse_bus_spec(bus_spec)[0] == "virtual":
            self._in_process = _open_stream_tap(bus_spec, self.path, limit)
            return
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "spacearm.controller.recording.can_trace", bus_spec, str(self.path),
             str(limit.max_bytes), str(limit.keep)],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=module_env(),
            preexec_fn=use_normal)
        # Wait for the tap to be on the bus so the trace covers the recording from its start.
        line = (readline_within(self._proc, start_timeout) or "").strip()
        if line != READY:
            self._proc.kill()
            self._proc.wait()
            raise RuntimeError(f"CAN trace did not start: {line or 'no answer'}")

    @property
    def pid(self) -> int | None:
        """The child process formatting the trace (for CPU accounting), None once stopped."""
        if self._proc is not None:
            return self._proc.pid if self._proc.poll() is None else None
        return self._in_process[2].pid if self._in_process is not None else None

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


def _open_tap(bus_spec: str, path: Path, limit: TraceLimit) -> tuple[can.BusABC, can.Notifier, RotatingTraceWriter]:
    tap = open_bus(bus_spec)
    writer = RotatingTraceWriter(path, limit)
    if hasattr(tap, "add_inline_listener"):
        # in-process bus: frames are appended in the sender's thread and formatted in batches
        # (base/transport/tap.py), not one Message, queue hop and write per frame on the cycle
        from spacearm.base.transport.tap import BufferedTap
        buffered = BufferedTap(writer, str(tap.channel_id), getattr(tap, "line_channels", None))
        tap.add_inline_listener(buffered)
        return tap, can.Notifier(tap, [buffered], timeout=0.1), buffered
    return tap, can.Notifier(tap, [writer], timeout=0.1), writer


def _open_stream_tap(bus_spec: str, path: Path, limit: TraceLimit) -> tuple[can.BusABC, can.Notifier, StreamTap]:
    """The in-process bus's tap: frames collected here, formatted by a child (trace_stream.py)."""
    tap = open_bus(bus_spec)
    stream = StreamTap(path, limit.max_bytes, limit.keep, str(tap.channel_id), getattr(tap, "line_channels", None))
    # a plain in-process bus takes it as a tap (no receiver queue, seen first); a pair inline
    getattr(tap, "add_tap", tap.add_inline_listener)(stream)
    return tap, can.Notifier(tap, [stream], timeout=0.1), stream


def _close_tap(tap: can.BusABC, notifier: can.Notifier, writer: RotatingTraceWriter) -> None:
    notifier.stop()
    tap.shutdown()
    writer.stop()


def main(argv: list[str] | None = None) -> int:
    args = argv if argv is not None else sys.argv[1:]
    bus_spec, path = args[:2]
    limit = TraceLimit(*(int(v) for v in args[2:4]))
    parent = os.getppid()
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    signal.signal(signal.SIGINT, lambda *_: done.set())
    try:
        tap, notifier, writer = _open_tap(bus_spec, Path(path), limit)
    except Exception as exc:
        print(f"can_trace: cannot open {bus_spec}: {exc}", flush=True)
        return 1
    print(READY, flush=True)
    # Lowered only once on the bus: started at niceness 10, on a busy machine (CI: 2 test
    # workers and their stacks) its start-up got the CPU last and outlasted the parent's 10 s.
    os.nice(CHILD_NICENESS)
    try:
        while not done.wait(FLUSH_INTERVAL) and os.getppid() == parent:
            writer.flush()
    finally:
        _close_tap(tap, notifier, writer)
    return 0


if __name__ == "__main__":
    sys.exit(main())
