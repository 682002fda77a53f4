"""Recordings are readable whole, and up to the last flush after a kill -9."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from spacearm.controller.recording.mcap_reader import RecordingError, read_recording
from spacearm.controller.recording.mcap_recorder import McapRecorder

SCHEMA = {"title": "sample", "type": "object", "properties": {"k": {"type": "integer"}}}
ROOT = Path(__file__).resolve().parents[2]


def test_clean_recording_round_trips_every_message(tmp_path):
    path = tmp_path / "run.mcap"
    with McapRecorder(path, metadata={"arm": "oru"}) as rec:
        rec.add_channel("/cycle", SCHEMA)
        for k in range(500):
            rec.write("/cycle", k * 0.02, {"k": k})
    recording = read_recording(path)
    assert recording.complete and not recording.problem
    assert [m.data["k"] for m in recording.topic("/cycle")] == list(range(500))
    assert [m.sequence for m in recording.messages] == list(range(1, 501))


def test_recording_killed_mid_run_is_readable_up_to_the_last_flushed_second(tmp_path):
    path = tmp_path / "killed.mcap"
    progress = tmp_path / "progress"
    writer = textwrap.dedent(f"""
        import time
        from spacearm.controller.recording.mcap_recorder import McapRecorder
        rec = McapRecorder({str(path)!r}, flush_interval=1.0)
        rec.add_channel("/cycle", {SCHEMA!r})
        k = 0
        while True:
            rec.write("/cycle", k * 0.02, {{"k": k}})
            if k % 50 == 0:
                open({str(progress)!r}, "w").write(str(k))
            k += 1
            time.sleep(0.0005)
    """)
    proc = subprocess.Popen([sys.executable, "-c", writer], cwd=ROOT)
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            if progress.exists() and progress.read_text() and int(progress.read_text() or 0) >= 300:
                break
            time.sleep(0.05)
        else:
            pytest.fail("writer made no progress")
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    last_reported = int(progress.read_text())
    recording = read_recording(path)
    assert not recording.complete
    ks = [m.data["k"] for m in recording.topic("/cycle")]
    # Contiguous from the start (nothing lost in the middle), and at most ~1 s (50 msgs at
    # 20 ms) plus the unflushed tail behind what the writer had reached.
    assert ks == list(range(len(ks)))
    assert len(ks) >= last_reported - 100


def test_non_mcap_file_is_a_clear_error(tmp_path):
    bogus = tmp_path / "bogus.mcap"
    bogus.write_bytes(b"hello, this is not mcap")
    with pytest.raises(RecordingError, match="not an MCAP file"):
        read_recording(bogus)
    with pytest.raises(RecordingError, match="cannot open"):
        read_recording(tmp_path / "absent.mcap")


def test_garbage_appended_after_data_keeps_earlier_messages(tmp_path):
    path = tmp_path / "damaged.mcap"
    rec = McapRecorder(path)
    rec.add_channel("/cycle", SCHEMA)
    for k in range(100):
        rec.write("/cycle", k * 0.02, {"k": k})
    rec.flush()
    with open(path, "ab") as handle:
        handle.write(os.urandom(64))
    recording = read_recording(path)
    assert [m.data["k"] for m in recording.messages] == list(range(100))
    assert not recording.complete and recording.problem
