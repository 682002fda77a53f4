"""The recording's serialisation runs in its own process (issue 35): the cycle only packs a
record. The file reads exactly as the cycle's message used to, and a kill -9 of either process
leaves it readable."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from spacearm.controller.cycle import EndEffectorState, MachineState
from spacearm.controller.daemon.recorder_process import WRITER_CHECK, RecorderProcess
from spacearm.controller.recording import mcap_recorder
from spacearm.controller.recording.mcap_reader import read_recording

ROOT = Path(__file__).resolve().parents[2]


def _cycle(k: int, n: int = 6) -> dict:
    """The /cycle message a daemon cycle built before the hand-off was packed (daemon._record
    as of issue 35), with values that vary in every field, odd floats included."""
    rng = np.random.default_rng(k)
    state = [MachineState.DISABLED, MachineState.ENABLED, MachineState.STOPPED][k // 7 % 3]
    missing = ("joint_3", "ft_sensor") if k % 11 == 5 else ()
    return {"t": k * 0.02, "sync": k % 240 + 1, "cycle": k, "q_cmd": rng.normal(size=n),
            "dq_cmd": list(rng.normal(size=n) * 1e-300 if k == 3 else rng.normal(size=n)),
            "q": rng.normal(size=n), "dq": rng.normal(size=n), "tau": rng.normal(size=n) * 1e3,
            "wrench": rng.normal(size=6), "end_effector": [EndEffectorState.NONE, EndEffectorState.UNKNOWN][k % 2],
            "state": state, "mode": "" if k < 20 else "joint_move", "period_error": float(rng.normal() * 1e-4),
            "execution": 1e-3 + k * 1e-9, "io_wait": 0.0 if k % 2 else 2.5e-4, "missing": missing}


def _old_json(c: dict) -> dict:
    message = {"t": c["t"], "sync": c["sync"], "cycle": c["cycle"], "q_cmd": c["q_cmd"].tolist(),
               "dq_cmd": c["dq_cmd"], "q": c["q"].tolist(), "dq": c["dq"].tolist(), "tau": c["tau"].tolist(),
               "wrench": c["wrench"].tolist(), "end_effector": c["end_effector"], "state": c["state"],
               "mode": c["mode"], "period_error": c["period_error"], "execution": c["execution"],
               "io_wait": c["io_wait"], **({"missing": list(c["missing"])} if c["missing"] else {})}
    return json.loads(json.dumps(message, separators=(",", ":")))


def _put(recorder: RecorderProcess, c: dict) -> None:
    recorder.put_cycle(c["t"], c["sync"], c["cycle"], c["q_cmd"], c["dq_cmd"], c["q"], c["dq"], c["tau"],
                       c["wrench"], c["end_effector"], c["state"], c["mode"], c["period_error"], c["execution"],
                       c["io_wait"], c["missing"])



def wait_until_ended(writer: int, timeout: float) -> None:
    """Wait for the writer process whose daemon was killed to end (exited, or a zombie)."""
    deadline = time.monotonic() + timeout
    while Path(f"/proc/{writer}").exists() and Path(f"/proc/{writer}/stat").read_text().split()[2] != "Z":
        if time.monotonic() > deadline:
            pytest.fail("the writer did not end after its daemon died")
        time.sleep(0.05)

def test_recorded_cycles_read_as_the_cycle_built_them_and_nothing_is_serialised_here(tmp_path, monkeypatch):
    def not_here(*args, **kwargs):
        raise AssertionError("MCAP serialised in the daemon's process")
    monkeypatch.setattr(mcap_recorder.McapRecorder, "write", not_here)
    path = tmp_path / "run.mcap"
    recorder = RecorderProcess(path, {"arm": "test"}, bus_spec=None, time_origin_ns=1_700_000_000 * 10**9)
    cycles = [_cycle(k) for k in range(60)]
    for c in cycles:
        _put(recorder, c)
        if c["cycle"] in (10, 40):      # events between cycles keep their place
            recorder.put("/events", c["t"], {"t": c["t"], "kind": "state", "message": f"after {c['cycle']}"})
    odd = {**_cycle(60), "dq_cmd": [0.5]}   # a layout the fixed record does not fit: sent whole, same content
    _put(recorder, odd)
    info = recorder.close()
    assert (info.cycles, info.dropped) == (61, 0)
    recording = read_recording(path)
    assert recording.complete, recording.problem
    assert [m.data for m in recording.topic("/cycle")] == [_old_json(c) for c in cycles + [odd]]
    # key order too: a reader that lists columns in file order sees the same columns
    assert [list(m.data) for m in recording.topic("/cycle")[:1]] == [list(_old_json(cycles[0]))]
    order = [(m.topic, m.data.get("cycle", m.data.get("message"))) for m in recording.messages]
    assert order[10:13] == [("/cycle", 10), ("/events", "after 10"), ("/cycle", 11)]
    assert [round(m.time, 9) for m in recording.topic("/cycle")] == [round(c["t"], 9) for c in cycles + [odd]]


def test_killed_writer_leaves_a_readable_file_and_the_cycle_carries_on(tmp_path):
    path = tmp_path / "run.mcap"
    recorder = RecorderProcess(path, {}, bus_spec=None)
    for k in range(300):
        _put(recorder, _cycle(k))
    time.sleep(2.5)       # the writer flushes within ~2 s of wall clock however little recording time passed
    os.kill(recorder.helper_pids()[0], signal.SIGKILL)
    recorder._writer.wait(10)
    time.sleep(WRITER_CHECK)       # the cycle looks at the writer this often (not a system call a cycle)
    for k in range(300, 400):      # never raises, never blocks: counted as dropped
        _put(recorder, _cycle(k))
    info = recorder.close()
    assert info.cycles == 300 and info.dropped == 100
    recording = read_recording(path)
    assert not recording.complete
    assert [m.data["cycle"] for m in recording.topic("/cycle")] == list(range(300))


def test_killed_daemon_leaves_every_cycle_it_handed_over(tmp_path):
    """SIGKILL of the daemon mid-run: the writer drains the ring and flushes; the file has no
    footer (nobody closed it) and holds every cycle handed over (the old in-process writer
    lost up to the last second)."""
    path, progress = tmp_path / "killed.mcap", tmp_path / "progress"
    daemon = textwrap.dedent(f"""
        import sys, time
        import numpy as np
        from spacearm.controller.daemon.recorder_process import RecorderProcess
        rec = RecorderProcess({str(path)!r}, {{}}, bus_spec=None)
        print(rec.helper_pids()[0], flush=True)
        z = np.zeros(6)
        k = 0
        while True:
            rec.put_cycle(k * 0.02, k % 240 + 1, k, z, [0.0] * 6, z, z, z, z, "none", "enabled", "", 0.0, 0.0, 0.0, ())
            if k % 50 == 0:
                open({str(progress)!r}, "w").write(str(k))
            k += 1
            time.sleep(0.0005)
    """)
    proc = subprocess.Popen([sys.executable, "-c", daemon], cwd=ROOT, stdout=subprocess.PIPE, text=True)
    try:
        writer = int(proc.stdout.readline())
        deadline = time.monotonic() + 30
        while not (progress.exists() and int(progress.read_text() or 0) >= 300):
            if time.monotonic() > deadline:
                pytest.fail("the daemon made no progress")
            time.sleep(0.05)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
    last_reported = int(progress.read_text())
    wait_until_ended(writer, 10)
    recording = read_recording(path)
    assert not recording.complete and recording.problem
    cycles = [m.data["cycle"] for m in recording.topic("/cycle")]
    assert cycles == list(range(len(cycles))) and len(cycles) > last_reported


def test_a_lockstep_recording_waits_for_a_starved_writer_instead_of_dropping(tmp_path):
    """Lockstep (lossless): a writer that gets no CPU (SIGSTOP stands in for a busy machine and
    its niceness) lets the ring fill; the cycle then waits for room, and every record reaches the
    file once the writer runs again. A real-time recorder drops and counts instead."""
    import threading
    path = tmp_path / "lockstep.mcap"
    recorder = RecorderProcess(path, {}, bus_spec=None, lossless=True, ring_bytes=1 << 20)
    writer = recorder.helper_pids()[0]
    os.kill(writer, signal.SIGSTOP)
    n = 4000                      # ~1.4 MB of records: more than the 1 MiB ring holds
    done = threading.Event()

    def cycles():
        for k in range(n):
            _put(recorder, _cycle(k))
        done.set()
    feeder = threading.Thread(target=cycles, daemon=True)
    feeder.start()
    try:
        assert not done.wait(1.5), "the cycle did not wait for the stopped writer"
    finally:
        os.kill(writer, signal.SIGCONT)
    assert done.wait(60)
    info = recorder.close()
    assert (info.cycles, info.dropped) == (n, 0)
    recording = read_recording(path)
    assert recording.complete, recording.problem
    assert [m.data["cycle"] for m in recording.topic("/cycle")] == list(range(n))
