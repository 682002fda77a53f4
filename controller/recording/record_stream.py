"""The byte stream from the control cycle to the recording writer process.

The cycle must not serialise MCAP (JSON per message, chunk compression, fsync): that cost
was ~25 % of a lockstep cycle's process CPU (issue 35). Instead it packs one fixed-size
binary record per cycle (numbers only, one precompiled struct straight into a shared-memory
ring, record_ring.py); the writer process (writer_process.py) turns the records back into
the same /cycle JSON messages as before and writes the MCAP file in batches.

Record = FRAME (payload length, kind) + payload:

    SETUP     JSON {"metadata", "time_origin_ns", "flush_interval"}; first, once
    LABELS    JSON [end_effector, state, mode, missing]: the /cycle strings, sent only when
              they change (a cycle record carries numbers only)
    CYCLE     CYCLE_HEAD (joints n, wrench w, t, sync, cycle, period_error, execution, io_wait)
              then 5n + w doubles: q_cmd, dq_cmd, q, dq, tau, wrench (packed by the daemon,
              controller/daemon/recorder_process.py; this module stays free of numpy so the
              writer process starts fast)
    MESSAGE   MESSAGE_HEAD (time, topic length), topic, JSON: any other message (/events, /stats)
    CLOSE     clean end: the writer adds the MCAP summary; a stream ending without it (the
              daemon died) leaves the file readable up to the last record, without a footer
"""
from __future__ import annotations

import json
import struct
from typing import Any, Iterator
FRAME = struct.Struct("<IB")
CYCLE_HEAD = struct.Struct("<HHdqqddd")
MESSAGE_HEAD = struct.Struct("<dH")
SETUP, LABELS, CYCLE, MESSAGE, CLOSE = range(5)
_COMPACT = (",", ":")
_doubles: dict[int, struct.Struct] = {}


def cycle_layout(joints: int, wrench: int) -> struct.Struct:
    """The daemon's side of a CYCLE record for an arm: one struct for the whole record, FRAME
    (payload length, CYCLE), CYCLE_HEAD and all 5n + w doubles, packed in one call."""
    return struct.Struct(FRAME.format + CYCLE_HEAD.format.lstrip("<") + f"{5 * joints + wrench}d")


def _frame(kind: int, payload: bytes) -> bytes:
    return FRAME.pack(len(payload), kind) + payload


def setup_record(metadata: dict[str, str], time_origin_ns: int, flush_interval: float) -> bytes:
    return _frame(SETUP, json.dumps({"metadata": metadata, "time_origin_ns": int(time_origin_ns),
                                     "flush_interval": flush_interval}).encode())


def labels_record(end_effector: str, state: str, mode: str, missing: tuple[str, ...]) -> bytes:
    return _frame(LABELS, json.dumps([end_effector, state, mode, list(missing)], separators=_COMPACT).encode())


def message_record(topic: str, time_s: float, message: dict[str, Any]) -> bytes:
    name = topic.encode()
    return _frame(MESSAGE, MESSAGE_HEAD.pack(time_s, len(name)) + name
                  + json.dumps(message, separators=_COMPACT).encode())


CLOSE_RECORD = _frame(CLOSE, b"")


class StreamDecoder:
    """Writer side: bytes in (any split), (kind, topic, time, message) out, in stream order."""

    def __init__(self) -> None:
        self._pending = b""
        self._labels: list = ["", "", "", []]

    def feed(self, data: bytes) -> Iterator[tuple[int, str, float, Any]]:
        buffer = self._pending + data if self._pending else data
        offset, end = 0, len(buffer)
        view = memoryview(buffer)
        while end - offset >= FRAME.size:
            length, kind = FRAME.unpack_from(buffer, offset)
            start = offset + FRAME.size
            if end - start < length:
                break
            payload = view[start:start + length]
            offset = start + length
            if kind == CYCLE:
                yield kind, "/cycle", *self._cycle(payload)
            elif kind == MESSAGE:
                time_s, size = MESSAGE_HEAD.unpack_from(payload)
                topic = bytes(payload[MESSAGE_HEAD.size:MESSAGE_HEAD.size + size]).decode()
                yield kind, topic, time_s, json.loads(bytes(payload[MESSAGE_HEAD.size + size:]))
            elif kind == LABELS:
                self._labels = json.loads(bytes(payload))
            elif kind == SETUP:
                yield kind, "", 0.0, json.loads(bytes(payload))
            elif kind == CLOSE:
                yield kind, "", 0.0, None
            else:
                raise ValueError(f"recording stream: unknown record kind {kind}")
        self._pending = bytes(view[offset:])

    def _cycle(self, payload: memoryview) -> tuple[float, dict[str, Any]]:
        n, w, t, sync, cycle, period_error, execution, io_wait = CYCLE_HEAD.unpack_from(payload)
        count = 5 * n + w
        layout = _doubles.get(count) or _doubles.setdefault(count, struct.Struct(f"<{count}d"))
        values = list(layout.unpack_from(payload, CYCLE_HEAD.size))
        end_effector, state, mode, missing = self._labels
        return t, cycle_message(t, sync, cycle, values[:n], values[n:2 * n], values[2 * n:3 * n],
                                values[3 * n:4 * n], values[4 * n:5 * n], values[5 * n:], end_effector, state,
                                mode, period_error, execution, io_wait, missing)


def cycle_message(t: float, sync: int, cycle: int, q_cmd: list, dq_cmd: list, q: list, dq: list, tau: list,
                  wrench: list, end_effector: str, state: str, mode: str, period_error: float, execution: float,
                  io_wait: float, missing) -> dict[str, Any]:
    """The /cycle message (channels.py), its keys in the order the cycle always built them, so
    the JSON reads the same and a reader listing columns in file order sees the same columns."""
    message = {"t": t, "sync": sync, "cycle": cycle, "q_cmd": q_cmd, "dq_cmd": dq_cmd, "q": q, "dq": dq,
               "tau": tau, "wrench": wrench, "end_effector": end_effector, "state": state, "mode": mode,
               "period_error": period_error, "execution": execution, "io_wait": io_wait}
    if missing:
        message["missing"] = list(missing)
    return message
