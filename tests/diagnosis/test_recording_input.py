"""Recordings from the real world: any CSV, columns by number with scale and offset, no
command, jittery / repeating / gapped time stamps, and --dry-run saying how it was read."""
from __future__ import annotations

import math

import numpy as np
import pytest
from typer.testing import CliRunner

from spacearm.console.main import app
from spacearm.offline.diagnosis.column_spec import ColumnSpecError, parse_columns
from spacearm.offline.diagnosis.csv_reader import read_any_csv
from spacearm.offline.diagnosis.recording_io import RecordingFormatError
from spacearm.offline.diagnosis.time_base import sync_time_base, uniform


def write(path, rows, header=None, sep=","):
    lines = ([sep.join(header)] if header else []) + [sep.join(f"{x:.9g}" for x in r) for r in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_column_expressions_scale_offset_ranges_and_units():
    specs = {s.ours: s for s in parse_columns("tau_3=#14*0.125, q_1=pos1*deg, q_2=#3*deg+1.5, dq_1..3=#5..7/2")}
    assert specs["tau_3"].source == 13 and specs["tau_3"].scale == 0.125
    assert specs["q_1"].source == "pos1" and specs["q_1"].scale == pytest.approx(math.pi / 180)
    assert specs["q_2"].offset == 1.5 and [specs[f"dq_{i}"].source for i in (1, 2, 3)] == [4, 5, 6]
    assert specs["dq_2"].scale == 0.5
    for bad in ("tau_3=#0", "q_1=pos*furlong", "x_1=#2", "q_1..3=#2..3", "q_1=#2,q_1=#3", "q_1=#2/0"):
        with pytest.raises(ColumnSpecError):
            parse_columns(bad)


def test_headerless_file_by_number_in_degrees_without_command(tmp_path):
    t = 0.01 * np.arange(200)
    q_deg = 10 * np.sin(t)[:, None] * np.array([1.0, 2.0])
    path = write(tmp_path / "rec.txt", np.column_stack([t * 1e3, q_deg, 8 * q_deg]), sep="\t")
    table, report = read_any_csv(path, parse_columns("t=#1*ms,q_1..2=#2..3*deg,tau_1..2=#4..5*0.125"), "measured")
    np.testing.assert_allclose(table.q, np.radians(q_deg), atol=1e-9)
    np.testing.assert_allclose(table.q_cmd, table.q)
    np.testing.assert_allclose(table.tau, q_deg, atol=1e-6)
    text = "\n".join(report.lines())
    assert "without a header" in text and "x 0.0174533" in text and "--command measured" in text
    with pytest.raises(RecordingFormatError, match="--command measured"):
        read_any_csv(path, parse_columns("t=#1*ms,q_1..2=#2..3*deg"))


def test_repeats_jitter_and_gaps_are_resampled_and_reported():
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.uniform(0.7e-3, 1.3e-3, 3000))
    q = np.sin(t)
    t_gap = np.delete(t, np.arange(1000, 1010))
    q_gap = np.delete(q, np.arange(1000, 1010))
    t_rep = np.insert(t_gap, 500, t_gap[500] + 1e-4)
    q_rep = np.insert(q_gap, 500, q_gap[499])
    grid, out, report = uniform(t_rep, {"q": q_rep})
    assert report.repeats_dropped == 1 and report.gaps >= 1 and report.resampled
    assert np.allclose(np.diff(grid), np.median(np.diff(grid)))
    np.testing.assert_allclose(out["q"], np.sin(grid), atol=1e-4)   # linear across a 10 ms gap


def test_sync_counter_rows_stay_cycles_when_the_controller_skipped_some():
    t = 0.02 * np.array([0, 1, 2, 5, 6, 7, 8, 9, 10, 11, 12, 13])       # two cycles skipped after row 2
    sync = (np.arange(len(t)) % 240) + 1
    np.testing.assert_allclose(sync_time_base(t, sync, 240), 0.02 * np.arange(len(t)))
    assert sync_time_base(t, np.ones(len(t)), 240) is None


def test_clocked_rows_with_jittery_stamps_keep_their_values():
    t = 0.02 * np.arange(100) + np.random.default_rng(1).uniform(-0.003, 0.003, 100)
    t[0] = 0.0
    q = np.arange(100.0)
    grid, out, report = uniform(t, {"q": q})
    assert report.snapped and len(grid) == 100
    np.testing.assert_array_equal(out["q"], q)


def test_dry_run_prints_how_each_column_was_read(tmp_path):
    t = 0.02 * np.arange(50)
    path = write(tmp_path / "r.csv", np.column_stack([t, np.sin(t), np.sin(t), 3 * np.cos(t)]),
                 ["time", "q1", "q_cmd1", "torque1"])
    res = CliRunner().invoke(app, ["diagnose", str(path), "--dry-run"])
    assert res.exit_code == 0, res.output
    assert "t        <- column 1 ('time')" in res.output and "tau_1    <- column 4 ('torque1')" in res.output
    assert "not in the recording (taken as 0, not compared): dq_1" in res.output


def test_a_cell_no_arm_can_reach_is_bridged_like_an_unreadable_one(tmp_path):
    """A lost delimiter joins two numbers into 1e+300-like cells; left in, they swamp every fit."""
    t = 0.02 * np.arange(100)
    tau = 5 * np.sin(t)
    rows = np.column_stack([t, np.sin(t), np.sin(t), tau])
    rows[40, 3] = 3.1e300
    path = write(tmp_path / "rec.csv", rows, header=["t", "q_cmd_1", "q_1", "tau_1"])
    table, report = read_any_csv(path, {})
    assert np.all(np.abs(table.tau) < 10) and abs(table.tau[40, 0] - tau[40]) < 0.05
    assert "1 unreadable cells, 1 of them beyond +-1e+09" in "\n".join(report.lines())
