"""The recording writer: a child process that turns the daemon's record stream (stdin,
record_stream.py) into an MCAP file, so its serialisation never runs in the daemon's interpreter.

    python -m spacearm.controller.recording.writer_process OUT.mcap   # what the daemon starts

It reads what has arrived every BATCH_PERIOD and writes it as one batch; McapRecorder closes
a chunk (and fsyncs) once per second of recording time, and this process also once per
FLUSH_WALL of wall clock, so a kill -9 of either process loses at most about a second. When
the daemon ends the stream cleanly (CLOSE) the file gets its summary; when the stream just
ends (the daemon died) everything received is flushed and the file stays without a footer,
readable, saying the writer did not close it.
"""
from __future__ import annotations

import os
import select
import signal
import sys
import time

from spacearm.controller.recording.channels import CHANNELS
from spacearm.controller.recording.mcap_recorder import McapRecorder
from spacearm.controller.recording.record_stream import CLOSE, SETUP, StreamDecoder

BATCH_PERIOD = 0.05   # s between reads: one wake-up per batch of cycles, not per cycle
FLUSH_WALL = 1.0      # s of wall clock between flushes at most (a paused lockstep run)
READ_SIZE = 1 << 20
NICENESS = 10         # the writer must never take CPU from the cycle


def run(path: str, stream_fd: int) -> int:
    decoder = StreamDecoder()
    recorder: McapRecorder | None = None
    written_at_flush, flushed_at = 0, time.monotonic()
    closed = False
    while not closed:
        # wait at most FLUSH_WALL for records: a paused run's last records still reach the disk
        if not select.select([stream_fd], [], [], FLUSH_WALL)[0]:
            data = b""
        elif not (data := os.read(stream_fd, READ_SIZE)):
            break                      # the daemon is gone without CLOSE
        for kind, topic, time_s, message in decoder.feed(data):
            if kind == SETUP:
                recorder = McapRecorder(path, flush_interval=message["flush_interval"],
                                        metadata=message["metadata"], time_origin_ns=message["time_origin_ns"])
                for name, schema in CHANNELS.items():
                    recorder.add_channel(name, schema)
            elif kind == CLOSE:
                closed = True
            elif recorder is not None:
                recorder.write(topic, time_s, message)
        if recorder is not None and recorder.messages_written != written_at_flush \
                and time.monotonic() - flushed_at >= FLUSH_WALL:
            recorder.flush()
            written_at_flush, flushed_at = recorder.messages_written, time.monotonic()
        if data and not closed:
            time.sleep(BATCH_PERIOD)
    if recorder is not None:
        if closed:
            recorder.close()
        else:
            recorder.flush()
    return 0


def main(argv: list[str] | None = None) -> int:
    args = argv if argv is not None else sys.argv[1:]
    # A terminal's Ctrl-C reaches the whole process group: the daemon closes the stream itself.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.nice(NICENESS)
    return run(args[0], sys.stdin.fileno())


if __name__ == "__main__":
    sys.exit(main())
