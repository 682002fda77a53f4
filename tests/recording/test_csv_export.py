import csv

import pytest

from spacearm.controller.recording.channels import CHANNELS
from spacearm.controller.recording.csv_export import export_csv
from spacearm.controller.recording.mcap_reader import RecordingError
from spacearm.controller.recording.mcap_recorder import McapRecorder


def cycle(k, n=6):
    return {"t": k * 0.02, "sync": k % 240 + 1, "cycle": k, "q_cmd": [0.1 * k] * n, "q": [0.1 * k - 0.001] * n,
            "dq": [0.0] * n, "tau": [1.5] * n, "wrench": [1, 2, 3, 0.1, 0.2, 0.3], "end_effector": "open",
            "state": "enabled", "mode": "hold", "period_error": 1e-4, "execution": 2e-3,
            "extra": {"temp_1": 20.0 + k}}


def record(path, ks):
    with McapRecorder(path) as rec:
        for topic, schema in CHANNELS.items():
            rec.add_channel(topic, schema)
        for k in ks:
            rec.write("/cycle", k * 0.02, cycle(k))


def test_export_writes_the_wide_csv_columns_in_order(tmp_path):
    record(tmp_path / "r.mcap", range(10))
    result = export_csv(tmp_path / "r.mcap", tmp_path / "r.csv")
    rows = list(csv.reader(open(tmp_path / "r.csv")))
    assert rows[0][:7] == ["t", "q_cmd_1", "q_cmd_2", "q_cmd_3", "q_cmd_4", "q_cmd_5", "q_cmd_6"]
    assert rows[0][25:31] == ["fx", "fy", "fz", "tx", "ty", "tz"]
    assert rows[0][-1] == "temp_1"
    assert len(rows) == 11 and result.rows == 10 and result.gaps == []
    assert float(rows[4][0]) == pytest.approx(0.06) and float(rows[4][7]) == pytest.approx(0.299)


def test_gaps_in_the_cycle_counter_are_reported_not_filled(tmp_path):
    record(tmp_path / "r.mcap", [0, 1, 2, 5, 6, 9])
    result = export_csv(tmp_path / "r.mcap", tmp_path / "r.csv")
    assert result.rows == 6
    assert result.gaps == [(pytest.approx(0.10), 2), (pytest.approx(0.18), 2)]


def test_recording_without_cycles_is_a_clear_error(tmp_path):
    record(tmp_path / "r.mcap", [])
    with pytest.raises(RecordingError, match="no /cycle messages"):
        export_csv(tmp_path / "r.mcap", tmp_path / "r.csv")
