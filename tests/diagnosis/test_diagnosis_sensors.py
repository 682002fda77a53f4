"""Sensor effects sized by the recording (issue 31): a velocity lag longer than the old fixed
6-cycle search, its search limit said when it is hit, a position column in degrees or off by
a constant named with its size, and every time-base repair in the JSON and report.md."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from spacearm.console.main import app
from spacearm.offline.diagnosis.analysis import diagnose
from spacearm.offline.diagnosis.record import record_direct
from spacearm.offline.diagnosis.sensor_effects import LAG_CAP, sensor_findings
from spacearm.offline.diagnosis.trajectory import Trajectory, save_trajectory
from spacearm.firmware_sim.plant import load_plant_config

NOMINAL = load_plant_config("configs/plant/oru_testbed_nominal.toml")
Q_HOME = np.array([0.0, math.pi / 2, -math.pi / 2, 0.0, -math.pi / 2, 0.0])


def _lagged(rate: float, cycles: int, seconds: float = 30.0, period: float = 4.0):
    dt = 1.0 / rate
    t = np.arange(0.0, seconds, dt)
    q = 0.4 * np.sin(2 * math.pi * t / period) + 0.1 * np.sin(2 * math.pi * t / (0.31 * period))
    v = np.gradient(q, dt)
    dq = np.r_[np.full(cycles, v[0]), v[:-cycles]]
    return q[:, None], dq[:, None], np.zeros((len(t), 1)), dt


@pytest.mark.parametrize("rate, cycles", [(50.0, 9), (100.0, 10), (100.0, 20)])
def test_a_velocity_lag_longer_than_six_cycles_is_sized(rate, cycles):
    q, dq, tau, dt = _lagged(rate, cycles)
    lag = [f for f in sensor_findings(q, dq, tau, dt, None, None, [0]) if f.effect == "velocity_latency"]
    assert len(lag) == 1
    assert lag[0].params["velocity_latency_cycles"] == cycles
    assert not lag[0].params["at_search_limit"]


def test_a_lag_at_the_search_limit_says_so():
    # a slow motion (correlation length past the cap) and a lag longer than the cap: the cap is reported
    q, dq, tau, dt = _lagged(100.0, LAG_CAP + 20, seconds=80.0, period=20.0)
    lag = [f for f in sensor_findings(q, dq, tau, dt, None, None, [0]) if f.effect == "velocity_latency"]
    assert lag and lag[0].params["at_search_limit"] and lag[0].params["search_limit_cycles"] == LAG_CAP
    assert f"limit of {LAG_CAP} cycles" in lag[0].text and "capped" in lag[0].text


def _recording(seconds: float = 16.0):
    t = np.arange(0.0, seconds, 0.02)
    traj = Trajectory(t, Q_HOME + 0.1 * np.sin(2 * math.pi * t[:, None] / np.array([5, 6, 7, 8, 9, 10])))
    plant = NOMINAL.model_copy(update={"joints": [j.model_copy(update={"torque_noise": 0.5}) for j in NOMINAL.joints]})
    return record_direct(plant, traj, None, hold_cycles=0), traj


def test_a_position_column_in_degrees_and_an_encoder_offset_are_named_with_their_size():
    table, _ = _recording()
    table.q[:, 1] = np.degrees(table.q[:, 1])
    table.q[:, 4] += 0.05
    result = diagnose(table, NOMINAL)
    by_effect = {(f.effect, f.joint): f for f in result.sensor_findings}
    assert ("position_units", 1) in by_effect, result.verdict
    assert by_effect[("position_units", 1)].params["scale"] == pytest.approx(180.0 / math.pi, rel=0.01)
    assert ("position_offset", 4) in by_effect, result.verdict
    assert by_effect[("position_offset", 4)].params["offset"] == pytest.approx(0.05, rel=0.05)
    assert "degrees" in result.verdict and "position column offset by 0.0" in result.verdict


def test_time_base_repairs_are_listed_in_the_json_and_report(tmp_path):
    table, traj = _recording(10.0)
    save_trajectory(tmp_path / "traj.csv", traj.t, traj.q)
    rec = tmp_path / "rec.csv"
    res = CliRunner().invoke(app, ["record-sim", "--plant", "configs/plant/oru_testbed_nominal.toml", "--trajectory", str(tmp_path / "traj.csv"), "--out", str(rec),
                                   "--direct"])
    assert res.exit_code == 0, res.output
    lines = rec.read_text().splitlines()
    # a logger that wrote three rows twice
    rec.write_text("\n".join(lines[:100] + [lines[100]] + lines[100:200] + [lines[200]] * 2 + lines[200:]) + "\n")
    res = CliRunner().invoke(app, ["diagnose", str(rec), "--report", str(tmp_path / "d"), "--json"])
    assert res.exit_code == 0, res.output
    repairs = json.loads(res.output)["time_base_repairs"]
    assert any("dropped 3 rows" in r for r in repairs), repairs
    assert "dropped 3 rows" in (tmp_path / "d" / "report.md").read_text()
