"""A passive tap for the in-process bus that costs the sending thread almost nothing.

python-can's way (a bus handle, its queue, a Notifier thread, a writer formatting every frame)
costs ~10 us per frame on the cycle's thread plus a thread wake-up per frame. This tap is an
inline listener of the in-process bus (base/transport `add_inline_listener`): a frame is one
list append in the sender's thread; a background thread formats the batch every
FLUSH_PERIOD, in the writer's own candump format, in arrival order.

    tap = open_bus("virtual:arm")
    buffered = BufferedTap(RotatingTraceWriter(path, limit), channel=tap.channel_id)   # controller/recording/can_trace.py
    tap.add_inline_listener(buffered)
    ...
    buffered.stop()          # formats what is left, closes the writer

On a redundant pair (`line_channels`: the two lines' names) each frame's line is the channel
column, as `candump -l any` names each frame's interface.
"""
from __future__ import annotations

import threading

import can

from .redundant import rx_state

FLUSH_PERIOD = 0.2   # s
WRITE_LINES = 256    # lines per write between a rotating writer's size checks


class BufferedTap(can.Listener):
    def __init__(self, writer: can.Listener, channel: str, line_channels: tuple[str, str] | None = None):
        # writer: candump format with `file`, `last_timestamp`, `rotate_if_full()` and `stop()`
        # (can_trace.RotatingTraceWriter: python-can's CanutilsLogWriter under a size limit)
        self.writer = writer
        self.channel = channel
        self.line_channels = line_channels
        if line_channels is not None:
            self.on_frame = self._on_pair_frame
        self._frames: list = []
        self._stop = threading.Event()
        self._lock = threading.Lock()        # formatting (flush thread vs stop), never the hot path
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="can-trace-tap", daemon=True)
        self._thread.start()

    @property
    def file(self):
        return self.writer.file

    # hot path: the sender's thread (list.append is atomic under the GIL)
    def on_frame(self, can_id: int, data: bytes, timestamp: float) -> None:
        self._frames.append((timestamp, can_id, data))

    def _on_pair_frame(self, can_id: int, data: bytes, timestamp: float) -> None:
        line = rx_state.line
        self._frames.append((timestamp, can_id, data, self.line_channels[line] if line is not None else self.channel))

    def on_message_received(self, msg: can.Message) -> None:
        line = getattr(rx_state, "line", None)
        if self.line_channels is not None and line is not None:
            msg = can.Message(timestamp=msg.timestamp, arbitration_id=msg.arbitration_id, data=msg.data,
                              is_extended_id=msg.is_extended_id, is_error_frame=msg.is_error_frame,
                              is_remote_frame=msg.is_remote_frame, dlc=msg.dlc, channel=self.line_channels[line],
                              check=False)
        self._frames.append(msg)

    def _run(self) -> None:
        while not self._stop.wait(FLUSH_PERIOD):
            self.flush()

    def flush(self) -> None:
        with self._lock:
            frames, self._frames = self._frames, []
            if not frames or self._closed:
                return     # after stop: the writer is closed (frames still in flight are dropped)
            writer = self.writer
            if writer.last_timestamp is None:
                first = frames[0]
                writer.last_timestamp = (first[0] if isinstance(first, tuple) else first.timestamp) or 0.0
            floor = writer.last_timestamp
            lines = []
            for item in frames:
                if isinstance(item, tuple):     # a received standard data frame, as the writer prints it
                    ts, can_id, data = item[:3]
                    channel = item[3] if len(item) > 3 else self.channel
                    lines.append(f"({max(ts, floor):f}) {channel} {can_id:03X}#{data.hex().upper()} R\n")
                    if len(lines) >= WRITE_LINES:
                        self._write(lines)
                        lines = []
                else:
                    self._write(lines)
                    lines = []
                    writer.on_message_received(item)
            self._write(lines)
            writer.file.flush()

    def _write(self, lines: list[str]) -> None:
        """Write formatted lines; a size-limited writer rotates between writes of at most
        WRITE_LINES lines, so a file overshoots its limit by at most one such write."""
        if lines:
            self.writer.file.write("".join(lines))
            self.writer.rotate_if_full()

    def stop(self) -> None:
        """Format what is left and close the writer; a second call (the Notifier stops its
        listeners, the owner stops the tap) does nothing."""
        if self._closed:
            return
        self._stop.set()
        self._thread.join(1.0)
        self.flush()
        with self._lock:
            self._closed = True
            self.writer.stop()
