"""The shared-memory ring between the cycle and the recording writer (record_ring.py): records
come out whole and in order across the ring's end, a full ring refuses a record instead of
overwriting one not yet taken, and only published bytes are read."""
from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

from spacearm.controller.recording.mcap_reader import read_recording
from spacearm.controller.recording.record_ring import RingConsumer, RingProducer
from spacearm.controller.recording.record_stream import CYCLE, StreamDecoder, cycle_layout, message_record
from tests.recording.test_recorder_process import wait_until_ended

ROOT = Path(__file__).resolve().parents[2]


def _consumer(producer: RingProducer) -> RingConsumer:
    return RingConsumer(os.dup(producer.fd))


def test_records_cross_the_ring_end_whole_and_in_order():
    producer = RingProducer(1000)          # not a multiple of any record size: every offset is hit
    consumer = _consumer(producer)
    rng = random.Random(7)
    sent, received = [], []
    for k in range(400):
        record = message_record("/events", k * 0.02, {"k": k, "pad": "x" * rng.randrange(0, 120)})
        if not producer.put(record):     # full: the consumer frees the room, then it fits
            received.append(consumer.take(consumer.published()))
            consumer.release()
            assert producer.put(record)
        sent.append(record)
        if rng.random() < 0.3:         # the consumer takes at random moments, as its wake-ups do
            received.append(consumer.take(consumer.published()))
            consumer.release()
    received.append(consumer.take(consumer.published()))
    assert b"".join(received) == b"".join(sent)
    assert producer.published > 20 * producer.capacity


def test_a_full_ring_refuses_a_record_and_keeps_what_was_not_taken():
    producer = RingProducer(100)
    consumer = _consumer(producer)
    assert producer.put(b"a" * 60)
    assert not producer.put(b"b" * 50)      # 110 > 100: refused, nothing written
    assert producer.put(b"c" * 40)
    assert producer.reserve(1) == -1
    assert consumer.take(consumer.published()) == b"a" * 60 + b"c" * 40
    assert producer.reserve(1) == -1        # taken but not released: still not free
    consumer.release()
    assert producer.put(b"d" * 100)          # wraps around the end
    assert consumer.take(consumer.published()) == b"d" * 100


def test_a_cycle_record_packed_in_place_or_across_the_end_decodes_the_same():
    layout = cycle_layout(6, 6)
    producer = RingProducer(3 * layout.size + 17)
    consumer = _consumer(producer)
    decoder = StreamDecoder()
    scratch = bytearray(layout.size)
    values = [[0.1 * k + j for j in range(36)] for k in range(12)]
    placed = set()
    for k, v in enumerate(values):
        at = producer.reserve(layout.size)
        assert at >= 0
        placed.add(bool(at))
        layout.pack_into(producer.map if at else scratch, at, layout.size - 5, CYCLE, 6, 6, k * 0.02, k % 240 + 1,
                         k, 1e-4, 2e-4, 3e-4, *v[:30], *v[30:])
        if not at:
            producer.copy(scratch)
        producer.publish(layout.size)
        decoded = list(decoder.feed(consumer.take(consumer.published())))
        consumer.release()
        assert [(kind, message["cycle"], message["q_cmd"], message["wrench"]) for kind, _, _, message in decoded] \
            == [(CYCLE, k, v[:6], v[30:])]
    assert placed == {True, False}          # both paths were taken


def test_bytes_written_but_not_published_are_not_read():
    producer = RingProducer(256)
    consumer = _consumer(producer)
    assert producer.put(b"whole")
    at = producer.reserve(4)
    producer.map[at:at + 4] = b"half"        # a record the daemon was killed in the middle of
    assert consumer.take(consumer.published()) == b"whole"
    assert consumer.take(consumer.published()) == b""


def test_a_daemon_killed_right_after_a_hand_over_leaves_every_record_it_handed_over(tmp_path):
    """The daemon hands over an exact number of cycles (the ring wrapping many times while the
    writer drains it) and then dies by SIGKILL with no chance to flush or close: the writer
    still writes every one of them, and the file reads without a footer."""
    path = tmp_path / "crash.mcap"
    n = 5000
    daemon = textwrap.dedent(f"""
        import os, signal, sys
        import numpy as np
        from spacearm.controller.daemon.recorder_process import RecorderProcess
        rec = RecorderProcess({str(path)!r}, {{}}, bus_spec=None, lossless=True, ring_bytes=64 * 1024)
        print(rec.helper_pids()[0], flush=True)
        for k in range({n}):
            rec.put_cycle(k * 0.02, k % 240 + 1, k, np.full(6, k * 1.0), [0.5] * 6, np.zeros(6), np.zeros(6),
                          np.zeros(6), np.zeros(6), "none", "enabled", "joint_move" if k > 100 else "", 0.0, 0.0,
                          0.0, ())
            if k == 2500:
                rec.put("/events", k * 0.02, {{"t": k * 0.02, "kind": "state", "message": "half way"}})
        assert (rec.cycles, rec.dropped) == ({n}, 0), (rec.cycles, rec.dropped)
        os.kill(os.getpid(), signal.SIGKILL)
    """)
    proc = subprocess.Popen([sys.executable, "-c", daemon], cwd=ROOT, stdout=subprocess.PIPE, text=True)
    writer = int(proc.stdout.readline())
    assert proc.wait(60) == -signal.SIGKILL
    wait_until_ended(writer, 20)
    recording = read_recording(path)
    assert not recording.complete and recording.problem
    cycles = recording.topic("/cycle")
    assert [m.data["cycle"] for m in cycles] == list(range(n))
    assert [m.data["q_cmd"][0] for m in cycles] == [float(k) for k in range(n)]
    assert [m.data["mode"] for m in cycles[100:102]] == ["", "joint_move"]
    assert [m.data["message"] for m in recording.topic("/events")] == ["half way"]
