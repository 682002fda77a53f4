"""The raw CAN trace of an in-process bus, formatted off the daemon's interpreter.

python-can's virtual bus exists only inside one process, so its tap must be an inline
listener there (base/transport `add_inline_listener`: one list append per frame in the
sender's thread). Formatting candump lines in this process cost ~0.15 ms of CPU per lockstep
cycle (issue 35), so every FLUSH_PERIOD a thread hands the frames collected so far to a child
process as one marshalled batch; the child formats them with base/transport/tap.py's
BufferedTap (the same lines, rotation by RotatingTraceWriter) and flushes each batch.

    python -m spacearm.controller.recording.trace_stream OUT.log MAX_BYTES KEEP CHANNEL [LINE_A LINE_B]

A daemon killed with SIGKILL loses the frames of its last FLUSH_PERIOD; the child formats
everything it received and ends at the end of its input.
"""
from __future__ import annotations

import marshal
import os
import signal
import struct
import subprocess
import sys
import threading
from pathlib import Path

import can

from spacearm.base.runtime.child_process import module_env
from spacearm.base.runtime.priority import use_normal
from spacearm.base.transport.redundant import rx_state

FLUSH_PERIOD = 0.2   # s
BATCH = struct.Struct("<I")
NICENESS = 10        # the trace must never take CPU from the cycle
# a frame that is not a plain standard data frame (can.Message): its flags, in this order
_FLAGS = ("is_extended_id", "is_error_frame", "is_remote_frame", "is_rx", "is_fd", "bitrate_switch",
          "error_state_indicator")


class StreamTap(can.Listener):
    """Inline listener of an in-process bus; its frames go to the formatting child in batches."""

    def __init__(self, path: Path, max_bytes: int, keep: int, channel: str,
                 line_channels: tuple[str, str] | None = None):
        self.line_channels = line_channels
        # One flat list for the tap's life (the hot path binds its extend): 3 values a frame (4 on a pair),
        # not a tuple a frame, so nothing the garbage collector tracks piles up between batches.
        self._frames: list = []
        extend = self._frames.extend
        if line_channels is None:
            self.on_frame = lambda can_id, data, timestamp: extend((timestamp, can_id, data))

            def on_frames(frames, timestamp: float) -> None:   # a burst (base/transport send_frames)
                for can_id, data in frames:
                    extend((timestamp, can_id, data))
            self.on_frames = on_frames
        else:
            self.on_frame = lambda can_id, data, timestamp: extend((timestamp, can_id, data, rx_state.line))
        self._stride = _stride(line_channels)
        self._stop = threading.Event()
        self._send_lock = threading.Lock()
        self._child = subprocess.Popen(
            [sys.executable, "-m", "spacearm.controller.recording.trace_stream", str(path), str(max_bytes),
             str(keep), channel, *(line_channels or ())],
            stdin=subprocess.PIPE, env=module_env(), preexec_fn=use_normal, start_new_session=True)
        self._thread = threading.Thread(target=self._run, name="can-trace-stream", daemon=True)
        self._thread.start()

    @property
    def pid(self) -> int:
        return self._child.pid

    # hot path: on_frame (bound in __init__) runs in the sender's thread, one list extend
    # (atomic under the GIL): timestamp, can_id, data[, line]

    def on_message_received(self, msg: can.Message) -> None:
        """Any other frame: its data slot holds everything the child needs to rebuild it."""
        line = getattr(rx_state, "line", None) if self.line_channels else None
        full = (bytes(msg.data), line, msg.dlc, msg.channel, tuple(bool(getattr(msg, name)) for name in _FLAGS))
        self._frames.extend((msg.timestamp, msg.arbitration_id, full, line)[:self._stride])

    def _run(self) -> None:
        while not self._stop.wait(FLUSH_PERIOD):
            self._send()

    def _send(self) -> None:
        with self._send_lock:
            frames = self._frames[:]       # frames appended meanwhile stay for the next batch
            del self._frames[:len(frames)]     # (whole frames: one extend is atomic under the GIL)
            if not frames or self._child.stdin.closed:
                return
            batch = marshal.dumps(frames)
            try:
                self._child.stdin.write(BATCH.pack(len(batch)) + batch)
                self._child.stdin.flush()
            except (BrokenPipeError, ValueError):
                pass     # the child is gone: the trace ends at its last batch

    def stop(self, timeout: float = 5.0) -> None:
        """Send what is left; the child formats it and closes the file. A second call does nothing."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join(1.0)
        self._send()
        with self._send_lock:
            try:
                self._child.stdin.close()
            except BrokenPipeError:
                pass
        try:
            self._child.wait(timeout)
        except subprocess.TimeoutExpired:
            self._child.kill()
            self._child.wait()


def _stride(line_channels) -> int:
    """Values a frame takes in a batch: timestamp, can_id, data, and on a pair its line."""
    return 3 if not line_channels else 4


def _deliver(buffered, frames: list, stride: int) -> None:
    """Feed a batch to the child's BufferedTap as the bus would have: each frame on its line."""
    for i in range(0, len(frames), stride):
        timestamp, can_id, data = frames[i:i + 3]
        if type(data) is tuple:        # a frame that is not a plain standard data frame
            data, line, dlc, channel, flags = data
            rx_state.line = line
            buffered.on_message_received(can.Message(timestamp=timestamp, arbitration_id=can_id, data=data,
                                                     dlc=dlc, channel=channel, check=False,
                                                     **dict(zip(_FLAGS, flags))))
        else:
            rx_state.line = frames[i + 3] if stride == 4 else None
            buffered.on_frame(can_id, data, timestamp)
    rx_state.line = None


def main(argv: list[str] | None = None) -> int:
    from spacearm.base.transport.tap import BufferedTap
    from spacearm.controller.recording.can_trace import RotatingTraceWriter, TraceLimit
    args = argv if argv is not None else sys.argv[1:]
    path, max_bytes, keep, channel, *lines = args
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # a terminal's Ctrl-C: the daemon ends the stream
    os.nice(NICENESS)
    buffered = BufferedTap(RotatingTraceWriter(Path(path), TraceLimit(int(max_bytes), int(keep))), channel,
                           tuple(lines) if lines else None)
    stream = sys.stdin.buffer
    try:
        while (head := stream.read(BATCH.size)) and len(head) == BATCH.size:
            size = BATCH.unpack(head)[0]
            batch = stream.read(size)
            if len(batch) < size:
                break        # the daemon died mid-batch
            _deliver(buffered, marshal.loads(batch), _stride(lines))
            buffered.flush()
    finally:
        buffered.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
