"""A recording whose velocity column runs a few milliseconds behind (or ahead of) its position
column (a logger's filtered velocity estimate, as on the real Panda recording of Gaz et al.:
dq/dt of q is dq 5-6 ms later). Under two 100 Hz cycles the whole-cycle velocity-lag search
never named it; the URDF diagnosis names it with its size, and nothing on columns that agree."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from spacearm.offline.diagnosis.arm_torque import arm_summary, diagnose_arm
from spacearm.offline.diagnosis.recording_io import RecordingTable
from spacearm.offline.diagnosis.rigid_body import inverse_dynamics, load_arm
from spacearm.offline.diagnosis.velocity_clock import velocity_lag

TWO_LINKS = """<robot name="two_links">
  <link name="base"/>
  <link name="upper"><inertial><origin xyz="0.3 0 0"/><mass value="8"/>
    <inertia ixx="0.4" iyy="0.4" izz="0.4" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="fore"><inertial><origin xyz="0.25 0 0"/><mass value="3"/>
    <inertia ixx="0.4" iyy="0.4" izz="0.4" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="300" velocity="3"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/><axis xyz="0 1 0"/>
    <origin xyz="0.6 0 0"/><limit lower="-3" upper="3" effort="100" velocity="3"/></joint>
</robot>
"""


def _fourier(t: np.ndarray, phase: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity and acceleration of a Swevers-type excitation (four harmonics)."""
    w, amp, k = 2 * math.pi * 0.1, np.array([0.5, 0.3, 0.2, 0.1]), np.arange(1, 5)
    arg = np.outer(t, k * w) + phase
    return ((amp / (k * w)) * np.sin(arg)).sum(1), (amp * np.cos(arg)).sum(1), (-amp * k * w * np.sin(arg)).sum(1)


def recording(tmp_path: Path, lag_s: float, seed: int):
    (tmp_path / "two_links.urdf").write_text(TWO_LINKS)
    arm = load_arm(tmp_path / "two_links.urdf", 2)
    t = np.arange(0.0, 24.0, 0.01)
    rng = np.random.default_rng(seed)
    phases = rng.uniform(0, 2 * math.pi, 2)
    now = [_fourier(t, p) for p in phases]
    late = [_fourier(t - lag_s, p) for p in phases]    # the velocity sample stamped t is the one at t - lag
    q = np.column_stack([x[0] for x in now])
    dq_true = np.column_stack([x[1] for x in now])
    tau = inverse_dynamics(arm, q, dq_true, np.column_stack([x[2] for x in now])) + 0.8 * np.sign(dq_true)
    dq = np.column_stack([x[1] for x in late]) + rng.normal(0.0, 0.002, q.shape)
    table = RecordingTable(t, q, q + rng.normal(0.0, 1e-5, q.shape), dq, tau + rng.normal(0.0, 0.05, q.shape),
                           np.zeros((len(t), 6)))
    return table, arm


@pytest.mark.parametrize("lag_s", [0.006, -0.004, 0.013])
def test_a_velocity_column_off_the_position_clock_is_named_with_its_size(tmp_path, lag_s):
    table, _ = recording(tmp_path, lag_s, seed=int(1e4 * abs(lag_s)))
    found = velocity_lag(table.t, table.q, table.dq, [0, 1])
    assert found is not None
    assert found.seconds == pytest.approx(lag_s, abs=0.001)


def test_columns_on_one_clock_name_no_lag(tmp_path):
    table, _ = recording(tmp_path, 0.0, seed=5)
    assert velocity_lag(table.t, table.q, table.dq, [0, 1]) is None


def test_the_arm_diagnosis_names_the_lag_in_its_verdict_and_json(tmp_path):
    table, arm = recording(tmp_path, 0.005, seed=7)
    d = diagnose_arm(table, arm)
    assert "velocity column dq runs 5 ms behind" in d.verdict
    assert arm_summary(d)["velocity_column_lag_s"] == pytest.approx(0.005, abs=0.001)
