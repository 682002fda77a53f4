"""The recording writer: a child process that turns the daemon's record stream
(record_stream.py, carried by the shared-memory ring of record_ring.py) into an MCAP file, so
its serialisation never runs in the daemon's interpreter.

    python -m spacearm.controller.recording.writer_process OUT.mcap RING_FD   # what the daemon starts

Every BATCH_PERIOD it takes what the ring holds and writes it as one batch; McapRecorder
closes a chunk (and fsyncs) once per second of recording time, and this process also once per
FLUSH_WALL of wall clock, so a kill -9 of the writer loses at most about a second. Its stdin
is the daemon's lifeline: nothing is written to it, and its end of file means the daemon has
closed the recording or died. Then the writer takes everything the ring still holds: after a
CLOSE record the file gets its summary; without one (the daemon died) every record handed over
is flushed and the file stays without a footer, readable, saying the writer did not close it.
"""
from __future__ import annotations

import os
import select
import signal
import sys
import time

from spacearm.controller.recording.channels import CHANNELS
from spacearm.controller.recording.mcap_recorder import McapRecorder
from spacearm.controller.recording.record_ring import RingConsumer
from spacearm.controller.recording.record_stream import CLOSE, SETUP, StreamDecoder

BATCH_PERIOD = 0.05   # s between takes: one wake-up per batch of cycles, not per cycle
FLUSH_WALL = 1.0      # s of wall clock between flushes at most (a paused lockstep run)
NICENESS = 10         # the writer must never take CPU from the cycle


def run(path: str, lifeline_fd: int, ring_fd: int) -> int:
    ring = RingConsumer(ring_fd)
    decoder = StreamDecoder()
    recorder: McapRecorder | None = None
    written_at_flush, flushed_at = 0, time.monotonic()
    seen = ring.published()
    closed = ended = False
    # the first take at once: the set-up record was published before this process was started
    # (a system call lies between), and with it the file exists as soon as the writer runs
    wait = 0.0
    while not (closed or ended):
        if select.select([lifeline_fd], [], [], wait)[0]:
            ended = not os.read(lifeline_fd, 4096)      # end of file: the daemon closed or died
        published = ring.published()
        # up to what was published a wake-up ago (record_ring.py), all of it once the daemon is gone
        data = ring.take(published if ended else seen)
        seen, wait = published, BATCH_PERIOD
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
        ring.release()
        if recorder is not None and recorder.messages_written != written_at_flush \
                and time.monotonic() - flushed_at >= FLUSH_WALL:
            recorder.flush()
            written_at_flush, flushed_at = recorder.messages_written, time.monotonic()
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
    return run(args[0], sys.stdin.fileno(), int(args[1]))


if __name__ == "__main__":
    sys.exit(main())
