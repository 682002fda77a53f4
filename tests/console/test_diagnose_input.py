"""`spacearm diagnose` on bad input (issue 33): a missing file is one coded line and the
bad-input exit code; a recording cut off by a killed writer is diagnosed on what it holds, with
a warning that says what was recovered (`export` said so; diagnose said nothing)."""
from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from spacearm.console.main import build_app
from spacearm.controller.recording.channels import CHANNELS
from spacearm.controller.recording.mcap_recorder import McapRecorder

PERIOD = 0.02


def cycle(k: int, n: int = 6) -> dict:
    q = [0.01 * k] * n
    return {"t": k * PERIOD, "sync": k % 240 + 1, "cycle": k, "q_cmd": q, "q": q, "dq": [0.5] * n, "tau": [1.0] * n,
            "wrench": [0.0] * 6, "end_effector": "open", "state": "enabled", "mode": "hold", "period_error": 0.0,
            "execution": 1e-3}


@pytest.fixture(scope="module")
def cut_recording(tmp_path_factory):
    """300 cycles flushed every 0.5 s of recording time, the last ~third cut off (no footer)."""
    path = tmp_path_factory.mktemp("diagnose") / "cut.mcap"
    with McapRecorder(path, flush_interval=0.5) as rec:
        for topic, schema in CHANNELS.items():
            rec.add_channel(topic, schema)
        for k in range(300):
            rec.write("/cycle", k * PERIOD, cycle(k))
    data = path.read_bytes()
    path.write_bytes(data[: 2 * len(data) // 3])
    return path


def diagnose(*args: str):
    return CliRunner().invoke(build_app(("diagnose",)), ["diagnose", *args])


@pytest.mark.parametrize("json_flag", [[], ["--json"]], ids=["text", "json"])
def test_a_missing_recording_is_one_coded_line_and_exit_2(tmp_path, json_flag):
    missing = tmp_path / "nowhere" / "run.mcap"
    done = diagnose(str(missing), *json_flag)
    assert done.exit_code == 2, done.output
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in done.output, done.output
    if json_flag:
        assert json.loads(lines[0]) == {"ok": False, "error": f"{missing}: no such file", "code": "bad_file", "exit": 2}
    else:
        assert lines[0] == f"error[bad_file]: {missing}: no such file"


def test_a_cut_off_recording_warns_what_was_recovered(cut_recording):
    done = diagnose(str(cut_recording), "--dry-run")
    assert done.exit_code == 0, done.output
    warning = [line for line in done.stderr.splitlines() if line.startswith("warning:")]
    assert len(warning) == 1, done.stderr
    # what the reader really got back: the cycles of the chunks that reached the disk
    from spacearm.controller.recording.mcap_reader import read_recording
    recovered = read_recording(cut_recording).topic("/cycle")
    assert 0 < len(recovered) < 300
    assert f"recovered {len(recovered)} cycles" in warning[0], warning
    assert f"t = 0.00 - {recovered[-1].time:.2f} s" in warning[0], warning
    assert "not closed cleanly" in warning[0] and "Traceback" not in done.output
