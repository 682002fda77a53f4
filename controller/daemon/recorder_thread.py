"""Recording off the control thread: the cycle hands over plain values, a writer thread
encodes them into MCAP and flushes once per second, so disk stalls never delay a cycle.

The raw CAN trace (candump .log) next to it comes from controller/recording/can_trace.py.
"""
from __future__ import annotations

import queue
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from spacearm.controller.recording.can_trace import CanTrace, TraceLimit
from spacearm.controller.recording.channels import CHANNELS
from spacearm.controller.recording.mcap_recorder import McapRecorder

QUEUE_LIMIT = 10_000  # cycles buffered if the disk stalls (200 s at 50 Hz) before dropping


@dataclass
class RecordingInfo:
    path: str
    can_log: str
    cycles: int
    dropped: int


class RecorderThread:
    def __init__(self, path: Path, metadata: dict[str, str], bus_spec: str | None,
                 time_origin_ns: int = 0, can_trace_limit: TraceLimit = TraceLimit()):
        """`time_origin_ns`: UTC wall clock of controller time 0 (the MCAP log times);
        `can_trace_limit`: size per raw CAN trace file and how many rotated files to keep."""
        self.path = Path(path)
        self.can_log = self.path.with_suffix(".can.log")
        self._recorder = McapRecorder(self.path, metadata=metadata, time_origin_ns=time_origin_ns)
        for topic, schema in CHANNELS.items():
            self._recorder.add_channel(topic, schema)
        self._queue: "queue.Queue[tuple[str, float, dict[str, Any]] | None]" = queue.Queue(QUEUE_LIMIT)
        self.cycles = 0
        self.dropped = 0
        self._thread = threading.Thread(target=self._run, name="recorder", daemon=True)
        self._thread.start()
        self._can_trace: CanTrace | None = None
        if bus_spec is not None:
            try:
                self._can_trace = CanTrace(bus_spec, self.can_log, limit=can_trace_limit)
            except Exception as exc:  # a trace is a bonus; the MCAP recording must not depend on it
                self.put("/events", 0.0, {"t": 0.0, "kind": "recording",
                                          "message": f"no raw CAN trace: {exc}"})

    def put(self, topic: str, t: float, message: dict[str, Any]) -> None:
        try:
            self._queue.put_nowait((topic, t, message))
            if topic == "/cycle":
                self.cycles += 1
        except queue.Full:
            self.dropped += 1

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is None:
                break
            self._recorder.write(*item)
        # A cycle that picked this recorder just before it was swapped out may still put
        # its message after the sentinel: write those too.
        while True:
            try:
                item = self._queue.get_nowait()
            except queue.Empty:
                return
            if item is not None:
                self._recorder.write(*item)

    def info(self) -> RecordingInfo:
        return RecordingInfo(str(self.path), str(self.can_log), self.cycles, self.dropped)

    def close(self, grace: float = 0.0) -> RecordingInfo:
        """Finish the file. `grace`: time for a cycle still holding this recorder to finish."""
        if grace:
            threading.Event().wait(grace)
        self._queue.put(None)
        self._thread.join(timeout=30)
        self._recorder.close()
        if self._can_trace is not None:
            self._can_trace.stop()
        return self.info()
