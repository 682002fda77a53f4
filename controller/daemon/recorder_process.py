"""Recording off the daemon's interpreter: the cycle packs one fixed-size record (numbers
only; the cycle's strings go only when they change) and writes it to a pipe; a child process
(controller/recording/writer_process.py) serialises MCAP in batches and flushes once per
second. A full pipe (the disk stalled for ~2500 cycles) drops records and counts them; it
never delays a cycle.

The raw CAN trace (candump .log) next to it comes from controller/recording/can_trace.py.
"""
from __future__ import annotations

import errno
import fcntl
import os
import select
import struct
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

PIPE_SIZE = 1 << 20          # bytes the pipe buffers while the writer is busy (Linux F_SETPIPE_SZ)
F_SETPIPE_SZ = 1031
LARGE_RECORD_WAIT = 1.0      # s a record above PIPE_BUF (a huge event) may wait for room
LOSSLESS_WAIT = 30.0         # s a lockstep cycle waits for room before the writer counts as stuck
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
                 flush_interval: float = 1.0, lossless: bool = False):
        """`time_origin_ns`: UTC wall clock of controller time 0 (the MCAP log times);
        `can_trace_limit`: size per raw CAN trace file and how many rotated files to keep;
        `lossless`: a full pipe makes the cycle wait instead of dropping the record (lockstep:
        nobody waits for the cycle's wall time, and a niced writer starved by a busy machine
        must not leave gaps that depend on the load)."""
        self._lossless = lossless
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.can_log = self.path.with_suffix(".can.log")
        self.cycles = 0
        self.dropped = 0
        self._lock = threading.Lock()   # a cycle's write against close() (never contended on the hot path)
        self._labels: tuple | None = None
        self._layout: tuple[int, int, struct.Struct, bytearray] | None = None   # joints, wrench, body, record
        self._writer = subprocess.Popen(
            [sys.executable, "-m", "spacearm.controller.recording.writer_process", str(self.path)],
            # its own session: a kill of the daemon's process group leaves it to drain the pipe
            stdin=subprocess.PIPE, env=module_env(), preexec_fn=use_normal, start_new_session=True)
        self._fd: int | None = self._writer.stdin.fileno()
        try:
            fcntl.fcntl(self._fd, F_SETPIPE_SZ, PIPE_SIZE)
        except OSError:
            pass                        # the default 64 KiB: ~160 cycles of slack
        self._send(record_stream.setup_record(metadata, time_origin_ns, flush_interval), wait=True)
        os.set_blocking(self._fd, False)
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
            frame, body = record_stream.cycle_layout(n, w)
            layout = self._layout = (n, w, body, bytearray(frame + bytes(body.size)))
        # one precompiled struct over plain floats into one reused buffer: a third of the CPU
        # of a numpy concatenation and three byte strings (issue 35)
        layout[2].pack_into(layout[3], record_stream.FRAME.size, n, w, t, sync, cycle, period_error, execution,
                            io_wait, *q_cmd.tolist(), *dq_cmd, *q.tolist(), *dq.tolist(), *tau.tolist(),
                            *wrench.tolist())
        if self._send(layout[3]):
            self.cycles += 1
        else:
            self.dropped += 1

    def put(self, topic: str, t: float, message: dict[str, Any]) -> None:
        if self._send(record_stream.message_record(topic, t, message)):
            if topic == "/cycle":
                self.cycles += 1
        else:
            self.dropped += 1

    def _send(self, record: bytes | bytearray, wait: bool = False) -> bool:
        """The record written whole (its buffer may be reused once this returns), or False."""
        with self._lock:
            if self._fd is None:
                return False
            try:
                if self._lossless:
                    try:
                        written = os.write(self._fd, record)     # all of it unless the pipe is nearly full
                    except BlockingIOError:
                        written = 0
                    return written == len(record) or self._write_all(memoryview(record)[written:], LOSSLESS_WAIT)
                if len(record) <= select.PIPE_BUF and not wait:
                    return os.write(self._fd, record) == len(record)   # atomic: all or nothing
                return self._write_all(record, LARGE_RECORD_WAIT)
            except BlockingIOError:
                return False
            except OSError as exc:
                if exc.errno == errno.EPIPE:      # the writer died: the file ends at its last flush
                    self._lossless = False         # or is stuck: the cycle stops waiting for it
                    return False
                raise

    def _write_all(self, record: bytes | memoryview, wait: float) -> bool:
        """A record written whole, in parts if the pipe has less room, waiting for room at
        most `wait` s (under the lock, so no other record interleaves)."""
        view, deadline = memoryview(record), time.monotonic() + wait
        while view:
            try:
                view = view[os.write(self._fd, view):]
            except BlockingIOError:
                if time.monotonic() > deadline:
                    raise OSError(errno.EPIPE, "recording writer too slow to take a record") from None
                time.sleep(0.001)
        return True

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
        self._send(record_stream.CLOSE_RECORD, wait=True)
        with self._lock:
            self._fd = None
            try:
                self._writer.stdin.close()
            except OSError:
                pass                    # the writer is gone already
        try:
            self._writer.wait(CLOSE_WAIT)
        except subprocess.TimeoutExpired:
            self._writer.kill()
            self._writer.wait()
        if self._can_trace is not None:
            self._can_trace.stop()
        return self.info()
