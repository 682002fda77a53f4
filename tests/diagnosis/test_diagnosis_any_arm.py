"""Recordings of another arm (its URDF, 7 joints), written as a stranger's header-less CSV in
degrees: friction named where the arm moved and nowhere else, ambiguity at one speed named
and an experiment within the URDF's limits designed for it."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from spacearm.console.main import app
from spacearm.offline.diagnosis.rigid_body import inverse_dynamics, load_arm

URDF = Path(__file__).resolve().parents[2] / "configs/urdf/panda/panda_arm_no_hand.urdf"
Q0 = np.array([0.0, -0.3, 0.0, -2.0, 0.0, 1.8, 0.8])


def recording(tmp_path: Path, q: np.ndarray, dt: float, coulomb: dict[int, float], viscous: dict[int, float],
              seed: int = 1) -> Path:
    """t [ms], q [deg], dq [deg/s], tau [N m / 0.01] in columns 1, 2-8, 9-15, 16-22; no header."""
    arm = load_arm(URDF, 7)
    dq = np.gradient(q, dt, axis=0)
    ddq = np.gradient(dq, dt, axis=0)
    tau = inverse_dynamics(arm, q, dq, ddq)
    for j, c in coulomb.items():
        tau[:, j] += c * np.tanh(dq[:, j] / 1e-3)
    for j, v in viscous.items():
        tau[:, j] += v * dq[:, j]
    tau += np.random.default_rng(seed).normal(0.0, 0.05, tau.shape)
    t = dt * np.arange(len(q))
    data = np.column_stack([1e3 * t, np.degrees(q), np.degrees(dq), tau / 0.01])
    path = tmp_path / "their_arm.txt"
    np.savetxt(path, data, delimiter=" ", fmt="%.8g")
    return path


def diagnose(path: Path, tmp_path: Path, *extra: str) -> dict:
    res = CliRunner().invoke(app, ["diagnose", str(path), "--columns",
                                   "t=#1*ms,q_1..7=#2..8*deg,dq_1..7=#9..15*deg,tau_1..7=#16..22*0.01",
                                   "--command", "measured", "--urdf", str(URDF), "--report", str(tmp_path / "d"),
                                   "--json", *extra])
    assert res.exit_code == 0, res.output
    return json.loads(res.output)


def test_friction_is_named_only_on_the_joints_that_moved(tmp_path):
    t = np.arange(0.0, 30.0, 0.01)
    q = np.repeat(Q0[None, :], len(t), axis=0)
    q[:, 0] += 0.6 * np.sin(2 * math.pi * t / 7.0) + 0.2 * np.sin(2 * math.pi * t / 2.3)
    q[:, 3] += 0.3 * np.sin(2 * math.pi * t / 5.0)
    out = diagnose(recording(tmp_path, q, 0.01, {0: 0.8, 3: 0.5, 5: 2.0}, {0: 0.3}), tmp_path)
    by_joint = {f["joint"]: f for f in out["findings"] if f["joint"] is not None}
    assert set(by_joint) == {1, 4}                   # joint 6's friction never showed: it did not move
    assert by_joint[1]["parameters"]["coulomb_friction"] == pytest.approx(0.8, rel=0.15)
    assert by_joint[4]["parameters"]["coulomb_friction"] == pytest.approx(0.5, rel=0.15)
    assert [j["moved"] for j in out["joints"]] == [True, False, False, True, False, False, False]
    assert all(j["heldout_rms_fitted"] < 0.5 * j["heldout_rms_nominal"] for j in out["joints"] if j["joint"] in (1, 4))


def test_one_speed_ramp_names_the_ambiguity_and_designs_an_experiment(tmp_path):
    t = np.arange(0.0, 20.0, 0.01)
    q = np.repeat(Q0[None, :], len(t), axis=0)
    q[:, 0] += 0.1 * np.clip(t - 1.0, 0.0, None)       # one way, one speed
    out = diagnose(recording(tmp_path, q, 0.01, {0: 0.8}, {}), tmp_path, "--experiment", str(tmp_path / "e.csv"))
    first = next(f for f in out["findings"] if f["joint"] == 1)
    assert "look alike" in first["text"]
    assert out["experiment"]["joints"] == [1]
    exp = np.loadtxt(tmp_path / "e.csv", delimiter=",", skiprows=1)
    arm = load_arm(URDF, 7)
    v = np.diff(exp[:, 1]) / np.diff(exp[:, 0])
    assert np.all(np.abs(v) <= arm.model.velocityLimit[0] + 1e-9)
    assert np.all((exp[:, 1] >= arm.model.lowerPositionLimit[0]) & (exp[:, 1] <= arm.model.upperPositionLimit[0]))
    assert len(np.unique(np.round(np.abs(v[np.abs(v) > 0.05]), 2))) >= 3          # several speeds
