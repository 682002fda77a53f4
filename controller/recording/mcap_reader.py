"""Read an MCAP recording, complete or cut off by a crash, into plain Python values."""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.records import Channel, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader


class RecordingError(Exception):
    """The file is not an MCAP recording, or is damaged before any readable data."""


@dataclass
class RecordedMessage:
    topic: str
    time: float  # s
    sequence: int
    data: dict[str, Any]


@dataclass
class Recording:
    path: Path
    messages: list[RecordedMessage] = field(default_factory=list)
    complete: bool = False   # True when the file ends with a footer (closed cleanly)
    problem: str = ""        # why reading stopped early, if it did

    def topic(self, name: str) -> list[RecordedMessage]:
        return [m for m in self.messages if m.topic == name]


def read_recording(path: str | Path, topics: set[str] | None = None) -> Recording:
    """Read every message that reached the disk (of `topics` if given), in file order.

    A truncated file (killed writer) yields the messages of every complete chunk and
    `complete=False` with the reason in `problem`; a file that is not MCAP at all raises.
    """
    path = Path(path)
    recording = Recording(path)
    channels: dict[int, Channel] = {}
    try:
        handle = open(path, "rb")
    except OSError as exc:
        raise RecordingError(f"{path}: cannot open: {exc.strerror}") from None
    origin_ns = 0
    with handle:
        head = handle.read(8)
        if head[:5] != b"\x89MCAP":
            raise RecordingError(f"{path}: not an MCAP file (bad magic)")
        handle.seek(0)
        try:
            for record in StreamReader(handle, validate_crcs=True).records:
                if isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    channel = channels.get(record.channel_id)
                    if channel is None or topics is not None and channel.topic not in topics:
                        continue
                    recording.messages.append(RecordedMessage(
                        channel.topic, (record.log_time - origin_ns) / 1e9, record.sequence,
                        json.loads(record.data)))
                elif isinstance(record, Footer):
                    recording.complete = True
                elif isinstance(record, Schema):
                    pass
                elif isinstance(record, Metadata) and record.name == "run":
                    # log times are UTC wall clock (mcap_recorder.py); give back controller time
                    origin_ns = int(record.metadata.get("log_time_origin_ns", "0") or 0)
        except (McapError, EOFError, ValueError, json.JSONDecodeError) as exc:
            recording.problem = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        except Exception as exc:  # truncated chunks surface as struct/zstd errors
            recording.problem = f"{type(exc).__name__}: {exc}"
    if not recording.complete and not recording.problem:
        recording.problem = "file ends without a footer (writer did not close it)"
    return recording
