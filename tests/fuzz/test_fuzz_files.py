"""Malformed configuration, EDS and recording files: a clear error naming the file (and the
key, for configs), never a traceback from deep inside a library."""
from __future__ import annotations

import tempfile
from pathlib import Path

import pytest
from hypothesis import given, strategies as st

from tests.fuzz.conftest import CaseCounter

ARM = Path("configs/arm/oru_testbed_6dof.toml")
EDS = Path("configs/eds/joint_drive.eds")


def mutate(text: bytes, data) -> bytes:
    """Delete, duplicate, replace or insert a few byte runs, or truncate."""
    out = bytearray(text)
    for _ in range(data.draw(st.integers(1, 4))):
        if not out:
            break
        op = data.draw(st.sampled_from(["delete", "replace", "insert", "truncate", "swapline"]))
        i = data.draw(st.integers(0, len(out) - 1))
        n = data.draw(st.integers(1, 40))
        if op == "delete":
            del out[i:i + n]
        elif op == "replace":
            out[i:i + n] = data.draw(st.binary(min_size=1, max_size=n))
        elif op == "insert":
            out[i:i] = data.draw(st.sampled_from([b"=", b"[", b"]", b"\n", b"-1e309", b"nan", b"\xff\xfe",
                                                  b'"', b"0x", b"$NODEID+", b"[x]\n"]))
        elif op == "truncate":
            del out[i:]
        else:
            lines = out.split(b"\n")
            j = data.draw(st.integers(0, len(lines) - 1))
            lines.insert(j, lines[data.draw(st.integers(0, len(lines) - 1))])
            out = bytearray(b"\n".join(lines))
    return bytes(out)


@given(data=st.data())
def test_mutated_arm_file_loads_or_names_the_problem(data):
    from spacearm.base.config.arm import load_arm_config
    from spacearm.base.config.errors import ConfigError
    CaseCounter.hit("files_arm_config")
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "arm.toml"
        path.write_bytes(mutate(ARM.read_bytes(), data))
        try:
            load_arm_config(path)
        except ConfigError as exc:
            message = str(exc)
            assert str(path) in message and "\n" not in message.strip() or str(path) in message


@given(data=st.data())
def test_mutated_eds_file_loads_or_names_the_problem(data):
    from spacearm.base.canopen.eds import EdsError, load_od
    CaseCounter.hit("files_eds")
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "joint_drive.eds"
        path.write_bytes(mutate(EDS.read_bytes(), data))
        try:
            load_od(path, 3)
        except EdsError as exc:
            assert str(path.resolve()) in str(exc) or str(path) in str(exc)


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> bytes:
    """A real recording: a few cycles written by the recorder, closed complete."""
    from spacearm.controller.recording.mcap_recorder import McapRecorder
    path = tmp_path_factory.mktemp("rec") / "run.mcap"
    rec = McapRecorder(path)
    rec.add_channel("/cycle", {"title": "cycle", "type": "object"})
    for i in range(200):
        rec.write("/cycle", i * 0.02, {"t": i * 0.02, "sync": i, "cycle": i, "q": [0.0] * 6})
    rec.close()
    return path.read_bytes()


@given(data=st.data())
def test_damaged_recording_reads_partially_or_names_the_problem(recording, data):
    from spacearm.controller.recording.mcap_reader import RecordingError, read_recording
    CaseCounter.hit("files_recording")
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "run.mcap"
        path.write_bytes(mutate(recording, data))
        try:
            rec = read_recording(path)
        except RecordingError as exc:
            assert str(path) in str(exc)
            return
        cycles = [m.data["cycle"] for m in rec.topic("/cycle")]
        assert cycles == sorted(cycles)
