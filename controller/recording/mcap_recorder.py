"""Crash-tolerant MCAP recorder with JSON-schema channels.

Messages are collected in chunks; the chunk in progress is closed and written to disk at
least once per `flush_interval` of recording time (and fsync'ed), so a run killed with
SIGKILL is readable up to the last flush. A clean `close()` adds the summary section.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from mcap.writer import CompressionType, Writer

PROFILE = "spacearm"


class McapRecorder:
    def __init__(self, path: str | Path, flush_interval: float = 1.0,
                 metadata: dict[str, str] | None = None, time_origin_ns: int = 0):
        """`time_origin_ns`: UTC wall-clock time (ns since the epoch) of message time 0, added to
        every log/publish time so Foxglove and the mcap CLI show the real date; kept in the
        metadata ("run": "log_time_origin_ns") so readers give back the controller's time."""
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")
        self._writer = Writer(self._file, compression=CompressionType.ZSTD)
        self._writer.start(profile=PROFILE, library="spacearm")
        self._origin_ns = int(time_origin_ns)
        self._writer.add_metadata("run", {**(metadata or {}), "log_time_origin_ns": str(self._origin_ns)})
        self._channels: dict[str, int] = {}
        self._sequence: dict[str, int] = {}
        self._flush_interval_ns = int(flush_interval * 1e9)
        self._last_flush_ns: int | None = None
        self.messages_written = 0
        self.closed = False

    def add_channel(self, topic: str, schema: dict[str, Any]) -> None:
        """Declare a topic with a JSON Schema (draft 2020-12, as Foxglove reads it)."""
        if topic in self._channels:
            raise ValueError(f"channel {topic!r} already declared")
        schema_id = self._writer.register_schema(
            name=schema.get("title", topic), encoding="jsonschema",
            data=json.dumps(schema).encode())
        self._channels[topic] = self._writer.register_channel(
            topic=topic, message_encoding="json", schema_id=schema_id)
        self._sequence[topic] = 0

    def write(self, topic: str, time_s: float, message: dict[str, Any]) -> None:
        if self.closed:
            raise RuntimeError(f"recording {self.path} is closed")
        channel_id = self._channels[topic]
        time_ns = int(round(time_s * 1e9))
        self._sequence[topic] += 1
        self._writer.add_message(channel_id=channel_id, log_time=self._origin_ns + time_ns,
                                 publish_time=self._origin_ns + time_ns,
                                 sequence=self._sequence[topic],
                                 data=json.dumps(message, separators=(",", ":")).encode())
        self.messages_written += 1
        if self._last_flush_ns is None:
            self._last_flush_ns = time_ns
        elif time_ns - self._last_flush_ns >= self._flush_interval_ns:
            self.flush()
            self._last_flush_ns = time_ns

    def flush(self) -> None:
        """Write the chunk in progress to disk; after this a crash loses nothing written so far."""
        self._writer.flush()
        os.fsync(self._file.fileno())

    def close(self) -> None:
        if self.closed:
            return
        self._writer.finish()
        self._file.flush()
        os.fsync(self._file.fileno())
        self._file.close()
        self.closed = True

    def __enter__(self) -> "McapRecorder":
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
