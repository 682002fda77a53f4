"""The commanded velocity offset (`dq_cmd`) in the recording formats: optional in the MCAP /cycle
channel and in the wide CSV. Files written before it was recorded, and other tools' CSVs, read as
before (no dq_cmd: the diagnosis rebuilds the offset from the targets where it was sent)."""
from __future__ import annotations

import copy
import csv
import math

import numpy as np

from spacearm.controller.recording.channels import CHANNELS, CYCLE_SCHEMA
from spacearm.controller.recording.csv_export import export_csv
from spacearm.controller.recording.mcap_recorder import McapRecorder
from spacearm.firmware_sim.plant import load_plant_config
from spacearm.offline.diagnosis.command_timing import replay_plant
from spacearm.offline.diagnosis.csv_reader import read_any_csv
from spacearm.offline.diagnosis.direct_sim import simulate
from spacearm.offline.diagnosis.recording_io import RecordingTable, read_recording, read_table, write_csv

NOMINAL = load_plant_config("configs/plant/oru_testbed_nominal.toml")
Q_HOME = np.array([0.0, math.pi / 2, -math.pi / 2, 0.0, -math.pi / 2, 0.0])
DT = 0.02


def _daemon_style_run(rows: int = 300):
    """Joint 3 out and back with the velocity offset sent, replayed directly (as the daemon's moves)."""
    t = DT * np.arange(rows)
    q_cmd = np.repeat(Q_HOME[None, :], rows, axis=0)
    q_cmd[:, 2] += 0.1 * (1.0 - np.cos(2 * math.pi * t / 4.0))
    dq_cmd = np.zeros_like(q_cmd)
    dq_cmd[:, 2] = 0.1 * 2 * math.pi / 4.0 * np.sin(2 * math.pi * t / 4.0)
    return simulate(NOMINAL, q_cmd, DT, dq_cmd=dq_cmd), dq_cmd


def _old_cycle_schema() -> dict:
    """The /cycle schema as it was before dq_cmd was recorded."""
    schema = copy.deepcopy(CYCLE_SCHEMA)
    del schema["properties"]["dq_cmd"]
    return schema


def _write_mcap(path, sim, dq_cmd=None, schema=None) -> None:
    with McapRecorder(path) as rec:
        for topic, channel_schema in CHANNELS.items():
            rec.add_channel(topic, schema if schema is not None and topic == "/cycle" else channel_schema)
        for k in range(len(sim.t)):
            row = {"t": float(sim.t[k]), "sync": k % 240 + 1, "cycle": k, "q_cmd": sim.q_cmd[k].tolist(),
                   "q": sim.q[k].tolist(), "dq": sim.dq[k].tolist(), "tau": sim.tau[k].tolist(),
                   "wrench": sim.wrench[k].tolist(), "end_effector": "none", "state": "enabled", "mode": "move"}
            if dq_cmd is not None:
                row["dq_cmd"] = dq_cmd[k].tolist()
            rec.write("/cycle", float(sim.t[k]), row)


def test_an_mcap_written_before_dq_cmd_reads_and_is_replayed_with_the_rebuilt_offset(tmp_path):
    sim, _ = _daemon_style_run()
    _write_mcap(tmp_path / "old.mcap", sim, schema=_old_cycle_schema())
    table, lines = read_recording(tmp_path / "old.mcap")
    assert table.dq_cmd is None and not any("dq_cmd" in line for line in lines)
    np.testing.assert_array_equal(table.q_cmd, sim.q_cmd)
    plant, note = replay_plant(table, NOMINAL)
    assert plant.planned_velocity_offset and "planned velocity" in note      # rebuilt from the targets
    result = export_csv(tmp_path / "old.mcap", tmp_path / "old.csv")
    assert not any(c.startswith("dq_cmd") for c in result.columns)
    assert read_table(tmp_path / "old.csv").dq_cmd is None


def test_an_mcap_with_dq_cmd_reads_it_and_its_csv_export_round_trips(tmp_path):
    sim, dq_cmd = _daemon_style_run()
    _write_mcap(tmp_path / "new.mcap", sim, dq_cmd)
    table, lines = read_recording(tmp_path / "new.mcap")
    np.testing.assert_array_equal(table.dq_cmd, dq_cmd)
    assert any("dq_cmd" in line for line in lines)
    export_csv(tmp_path / "new.mcap", tmp_path / "new.csv")
    header = next(csv.reader(open(tmp_path / "new.csv")))
    assert header[:7] == ["t"] + [f"q_cmd_{i}" for i in range(1, 7)]        # old columns keep their places
    assert header[header.index("execution") + 1:header.index("execution") + 7] == [f"dq_cmd_{i}" for i in range(1, 7)]
    np.testing.assert_array_equal(read_table(tmp_path / "new.csv").dq_cmd, dq_cmd)
    measured, _ = read_recording(tmp_path / "new.mcap", command="measured")
    assert measured.dq_cmd is None        # the measured motion carries its own velocity: no offset on top


def test_our_csv_writer_round_trips_dq_cmd_and_leaves_it_out_when_unknown(tmp_path):
    sim, dq_cmd = _daemon_style_run()
    table = RecordingTable(sim.t, sim.q_cmd, sim.q, sim.dq, sim.tau, sim.wrench, dq_cmd=dq_cmd)
    write_csv(tmp_path / "with.csv", table)
    back = read_table(tmp_path / "with.csv")
    np.testing.assert_allclose(back.dq_cmd, dq_cmd, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(back.rows(slice(5, 20)).dq_cmd, dq_cmd[5:20], rtol=1e-9, atol=1e-15)
    write_csv(tmp_path / "without.csv", RecordingTable(sim.t, sim.q_cmd, sim.q, sim.dq, sim.tau, sim.wrench))
    assert "dq_cmd" not in open(tmp_path / "without.csv").readline()
    assert read_table(tmp_path / "without.csv").dq_cmd is None


def test_a_users_csv_with_some_dq_cmd_columns_fills_the_rest_with_zero_and_says_so(tmp_path):
    sim, dq_cmd = _daemon_style_run(50)
    names = ["time"] + [f"q{i}" for i in range(1, 7)] + [f"q_cmd_{i}" for i in range(1, 7)] + ["dq_cmd_3"]
    data = np.column_stack([sim.t, sim.q, sim.q_cmd, dq_cmd[:, 2]])
    np.savetxt(tmp_path / "user.csv", data, delimiter=",", header=",".join(names), comments="", fmt="%.12g")
    table, report = read_any_csv(tmp_path / "user.csv")
    np.testing.assert_allclose(table.dq_cmd[:, 2], dq_cmd[:, 2], atol=1e-12)
    assert not table.dq_cmd[:, [0, 1, 3, 4, 5]].any()
    assert any("dq_cmd_1" in note and "taken as 0" in note for note in report.notes), report.notes
