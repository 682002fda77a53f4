"""The direct simulation path records what the CAN path records, for the same plant and commands."""
from __future__ import annotations

import math

import numpy as np

from spacearm.offline.diagnosis.record import record_can, record_direct
from spacearm.offline.diagnosis.recording_io import read_table
from spacearm.offline.diagnosis.trajectory import Trajectory
from spacearm.firmware_sim.plant import ARCSEC, load_plant_config

Q_HOME = np.array([0.0, math.pi / 2, -math.pi / 2, 0.0, -math.pi / 2, 0.0])


OFF_GRID = np.array([0.0123, 0.0071, -0.0093, 0.0, 0.004, -0.011])   # start between resolver steps


def _trajectory(seconds: float = 6.0, start: np.ndarray = Q_HOME) -> Trajectory:
    t = np.arange(0.0, seconds, 0.02)
    return Trajectory(t, start + 0.05 * np.sin(2 * math.pi * t[:, None] / np.array([3, 4, 5, 6, 7, 8])))


def _plant(resolver_arcsec: float):
    cfg = load_plant_config("configs/plant/oru_testbed_nominal.toml")
    joints = [j.model_copy(update={"resolver_arcsec": resolver_arcsec, "coulomb_friction": 2.0 if i == 2 else 0.0,
                                   "feedback_latency_cycles": 1 if i == 1 else 0})
              for i, j in enumerate(cfg.joints)]
    return cfg.model_copy(update={"joints": joints, "ft": cfg.ft.model_copy(update={"bias": (1.0, 0, 0, 0, 0, 0)})})


def _both(tmp_path, plant, start=Q_HOME):
    traj = _trajectory(start=start)
    can = read_table(record_can(plant, traj, tmp_path / "can.csv"))
    direct = record_direct(plant, traj, None, hold_cycles=0)
    # the CAN recording starts a few hold cycles before the trajectory (recording starts, then
    # the motion is submitted): align on the commands
    mismatch = [np.abs(can.q_cmd[lead:lead + 50] - direct.q_cmd[:50]).max() for lead in range(6)]
    lead = int(np.argmin(mismatch))
    assert mismatch[lead] < 1e-9
    can = can.rows(slice(lead, None))
    rows = min(len(can.t), len(direct.t))
    return can, direct, rows


def test_direct_path_equals_can_path_with_ideal_resolvers(tmp_path):
    can, direct, rows = _both(tmp_path, _plant(0.0))
    assert rows >= 299
    for name in ("q_cmd", "q", "dq", "tau", "wrench"):
        np.testing.assert_allclose(getattr(can, name)[:rows], getattr(direct, name)[:rows], atol=1e-9, err_msg=name)


def test_direct_path_matches_can_path_within_quantisation(tmp_path):
    can, direct, rows = _both(tmp_path, _plant(25.0), Q_HOME + OFF_GRID)
    quantum = 25.0 * ARCSEC
    assert np.max(np.abs(can.q[:rows] - direct.q[:rows])) <= 2 * quantum
    # the servo turns a resolver step into a torque step of about Kp * quantum (8.6 N m here);
    # the quantisation chatter differs row by row, its effect on the mean does not
    diff = can.tau[:rows] - direct.tau[:rows]
    assert np.max(np.abs(diff)) <= 3 * 8.9
    assert np.all(np.abs(diff.mean(axis=0)) < 0.5)
