"""Recording off the daemon's interpreter: the cycle packs one fixed-size record (numbers
only; the cycle's strings go only when they change) straight into a shared-memory ring
(controller/recording/record_ring.py), no system call; a child process
(controller/recording/writer_process.py) takes what the ring holds every 50 ms, serialises
MCAP in batches and flushes once per second. The ring outlives the daemon: a daemon that dies
leaves the writer every record it handed over. A full ring (the disk stalled for ~11000
cycles) drops records and counts them; it never delays a real-time cycle.

The raw CAN trace (candump .log) next to it comes from controller/recording/can_trace.py.
"""
from __future__ import annotations

import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spacearm.base.runtime.child_process import module_env
from spacearm.base.runtime.priority import use_normal
from spacearm.controller.recording import record_stream
from spacearm.controller.recording.can_trace import CanTrace, TraceLimit
from spacearm.controller.recording.record_ring import RingProducer

RING_BYTES = 4 << 20         # the ring: ~11000 cycle records of a 6-joint arm (~360 bytes each)
LARGE_RECORD_WAIT = 1.0      # s the CLOSE record may wait for room
LOSSLESS_WAIT = 30.0         # s a lockstep cycle waits for room before the writer counts as stuck
WRITER_CHECK = 0.1           # s between looks at whether the writer process still runs
CLOSE_WAIT = 30.0            # s for the writer to finish the file


@dataclass
class RecordingInfo:
    path: str
    can_log: str
    cycles: int
    dropped: int


class RecorderProcess:
    def __init__(self, path: Path, metadata: dict[str, str], bus_spec: str | None,
                 time_origin_ns: int = 0, can_trace_limit: TraceLimit = TraceLimit(),
                 flush_interval: float = 1.0, lossless: bool = False, ring_bytes: int = RING_BYTES):
        """`time_origin_ns`: UTC wall clock of controller time 0 (the MCAP log times);
        `can_trace_limit`: size per raw CAN trace file and how many rotated files to keep;
        `lossless`: a full ring makes the cycle wait instead of dropping the record (lockstep:
        nobody waits for the cycle's wall time, and a niced writer starved by a busy machine
        must not leave gaps that depend on the load); `ring_bytes`: the ring's size."""
        self._lossless = lossless
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.can_log = self.path.with_suffix(".can.log")
        self.cycles = 0
        self.dropped = 0
        self._lock = threading.Lock()   # a cycle's hand-over against close() (never contended on the hot path)
        self._labels: tuple | None = None
        self._layout: tuple[int, int, Any, bytearray] | None = None   # joints, wrench, record struct, scratch
        self._ring: RingProducer | None = RingProducer(ring_bytes)
        self._ring.put(record_stream.setup_record(metadata, time_origin_ns, flush_interval))
        self._writer = subprocess.Popen(
            [sys.executable, "-m", "spacearm.controller.recording.writer_process", str(self.path),
             str(self._ring.fd)],
            # stdin: the writer's lifeline (end of file: the daemon closed the recording or died);
            # its own session: a kill of the daemon's process group leaves it to drain the ring
            stdin=subprocess.PIPE, pass_fds=(self._ring.fd,), env=module_env(), preexec_fn=use_normal,
            start_new_session=True)
        self._next_check = time.monotonic() + WRITER_CHECK
        self._can_trace: CanTrace | None = None
        if bus_spec is not None:
            try:
                self._can_trace = CanTrace(bus_spec, self.can_log, limit=can_trace_limit)
            except Exception as exc:  # a trace is a bonus; the MCAP recording must not depend on it
                self.put("/events", 0.0, {"t": 0.0, "kind": "recording",
                                          "message": f"no raw CAN trace: {exc}"})

    def put_cycle(self, t: float, sync: int, cycle: int, q_cmd: np.ndarray, dq_cmd: list[float],
                  q: np.ndarray, dq: np.ndarray, tau: np.ndarray, wrench: np.ndarray, end_effector: str,
                  state: str, mode: str, period_error: float, execution: float, io_wait: float,
                  missing: tuple[str, ...]) -> None:
        """The /cycle message (channels.py), handed over as one packed record."""
        if len(dq_cmd) != len(q):       # not the fixed layout: as a whole message, same content
            self.put("/cycle", t, record_stream.cycle_message(
                t, sync, cycle, q_cmd.tolist(), list(dq_cmd), q.tolist(), dq.tolist(), tau.tolist(), wrench.tolist(),
                end_effector, state, mode, period_error, execution, io_wait, missing))
            return
        labels = (end_effector, state, mode, missing)
        if labels != self._labels:
            # a dropped label record must not leave the writer with stale strings: resend next time
            self._labels = labels if self._send(record_stream.labels_record(*labels)) else None
            if self._labels is None:
                self.dropped += 1
                return
        n, w = len(q), len(wrench)
        layout = self._layout
        if layout is None or layout[0] != n or layout[1] != w:
            record = record_stream.cycle_layout(n, w)
            layout = self._layout = (n, w, record, bytearray(record.size))
        record, scratch = layout[2], layout[3]
        size = record.size
        with self._lock:
            ring = self._ring
            at = ring.reserve(size) if ring is not None and time.monotonic() < self._next_check else -1
            if at < 0:                  # the ring is full, the writer is due a look, or recording is closed
                if not (ring is not None and self._room(ring, size)):
                    self.dropped += 1
                    return
                at = ring.reserve(size)
            # one precompiled struct over plain floats, straight into the shared ring (into the
            # scratch buffer only when the record wraps around the ring's end)
            record.pack_into(ring.map if at else scratch, at, size - record_stream.FRAME.size,
                             record_stream.CYCLE, n, w, t, sync, cycle, period_error, execution, io_wait,
                             *q_cmd.tolist(), *dq_cmd, *q.tolist(), *dq.tolist(), *tau.tolist(), *wrench.tolist())
            if not at:
                ring.copy(scratch)
            ring.publish(size)
            self.cycles += 1

    def put(self, topic: str, t: float, message: dict[str, Any]) -> None:
        if self._send(record_stream.message_record(topic, t, message)):
            if topic == "/cycle":
                self.cycles += 1
        else:
            self.dropped += 1

    def _send(self, record: bytes | bytearray) -> bool:
        """The record handed over whole, or False."""
        with self._lock:
            ring = self._ring
            if ring is None or not self._room(ring, len(record)):
                return False
            ring.copy(record)
            ring.publish(len(record))
            return True

    def _room(self, ring: RingProducer, size: int) -> bool:
        """Room for `size` bytes in a ring a live writer drains (under the lock). Lossless: waits
        for it, at most LOSSLESS_WAIT s, then counts the writer as stuck and stops waiting."""
        now = time.monotonic()
        if now >= self._next_check:     # a system call, so only now and then
            self._next_check = now + WRITER_CHECK
            if self._writer.poll() is not None:
                self._writer_gone()
                return False
        if ring.room(size):
            return True
        if size > ring.capacity or not self._lossless:
            return False
        deadline = now + LOSSLESS_WAIT
        while not ring.room(size):
            if self._writer.poll() is not None:
                self._writer_gone()
                return False
            if time.monotonic() > deadline:
                self._lossless = False   # stuck: the cycle stops waiting for it
                return False
            time.sleep(0.001)
        return True

    def _writer_gone(self) -> None:
        """The writer died: the file ends at its last flush; nothing more is handed over."""
        self._ring.close()
        self._ring = None

    def helper_pids(self) -> list[int]:
        """The processes doing the recording's work off the daemon (MCAP writer, CAN trace)."""
        trace = self._can_trace.pid if self._can_trace is not None else None
        return [self._writer.pid] + ([trace] if trace is not None else [])

    def info(self) -> RecordingInfo:
        return RecordingInfo(str(self.path), str(self.can_log), self.cycles, self.dropped)

    def close(self, grace: float = 0.0) -> RecordingInfo:
        """Finish the file. `grace`: time for a cycle still holding this recorder to finish."""
        if grace:
            threading.Event().wait(grace)
        with self._lock:
            ring, self._ring = self._ring, None
            if ring is not None:
                deadline = time.monotonic() + LARGE_RECORD_WAIT
                while not ring.put(record_stream.CLOSE_RECORD) and time.monotonic() < deadline \
                        and self._writer.poll() is None:
                    time.sleep(0.001)      # no CLOSE: the writer ends the file without its summary
                ring.close()
            try:
                self._writer.stdin.close()  # end of file: the writer takes what is left and ends
            except OSError:
                pass
        try:
            self._writer.wait(CLOSE_WAIT)
        except subprocess.TimeoutExpired:
            self._writer.kill()
            self._writer.wait()
        if self._can_trace is not None:
            self._can_trace.stop()
        return self.info()
