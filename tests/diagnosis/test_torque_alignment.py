"""A recording whose torque column runs a few milliseconds ahead of its motion columns (a
logger stamping the torque sensor and the filtered velocity apart): the URDF diagnosis names
the offset with its size and fits friction on the re-aligned torques. Unaligned, the
mismatch M q''' L looks like friction: the Coulomb level came out 60 % high on the real Panda's
joint 2 (tests/diagnosis/test_diagnosis_real_panda.py holds that case)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from spacearm.offline.diagnosis.arm_torque import accelerations, arm_summary, diagnose_arm
from spacearm.offline.diagnosis.recording_io import RecordingTable
from spacearm.offline.diagnosis.rigid_body import inverse_dynamics, load_arm
from spacearm.offline.diagnosis.torque_alignment import torque_time_offset

LINK = '<link name="{0}"><inertial><origin xyz="{1}"/><mass value="{2}"/>' \
       '<inertia ixx="0.4" iyy="0.4" izz="0.4" ixy="0" ixz="0" iyz="0"/></inertial></link>'
TWO_LINKS = f"""<robot name="two_links">
  <link name="base"/>
  {LINK.format("upper", "0.3 0 0", 8.0)}
  {LINK.format("fore", "0.25 0 0", 3.0)}
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="300" velocity="3"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/><axis xyz="0 0 1"/>
    <origin xyz="0.6 0 0"/><limit lower="-3" upper="3" effort="100" velocity="3"/></joint>
</robot>
"""
COULOMB = (1.5, 0.6)         # N m
VISCOUS = (0.8, 0.3)         # N m s / rad


def recording(tmp_path: Path, lead_s: float):
    (tmp_path / "two_links.urdf").write_text(TWO_LINKS)
    arm = load_arm(tmp_path / "two_links.urdf", 2)
    dt, fine = 0.01, 0.001
    tf = np.arange(0.0, 30.0, fine)
    # Fourier-series excitation (Swevers et al.): a few harmonics of one base frequency per joint
    w = 2 * math.pi * 0.1
    amp = np.array([[0.5, 0.3, 0.2, 0.1], [0.6, 0.4, 0.2, 0.15]])
    k = np.arange(1, 5)
    q = np.stack([(amp[j] / (k * w) * np.sin(np.outer(tf, k * w) + j)).sum(1) for j in range(2)], 1)
    dq = np.stack([(amp[j] * np.cos(np.outer(tf, k * w) + j)).sum(1) for j in range(2)], 1)
    ddq = np.stack([(-amp[j] * k * w * np.sin(np.outer(tf, k * w) + j)).sum(1) for j in range(2)], 1)
    tau = inverse_dynamics(arm, q, dq, ddq) + np.asarray(COULOMB) * np.sign(dq) + np.asarray(VISCOUS) * dq
    t = np.arange(0.0, 29.9, dt)
    at = lambda x, when: np.column_stack([np.interp(when, tf, x[:, j]) for j in range(2)])
    noise = np.random.default_rng(11).normal(0.0, 0.05, (len(t), 2))
    # the torque sample stamped t is the one the motion shows at t + lead
    table = RecordingTable(t, at(q, t), at(q, t), at(dq, t), at(tau, t + lead_s) + noise, np.zeros((len(t), 6)))
    return table, arm


@pytest.fixture(scope="module")
def shifted_result(tmp_path_factory):
    table, arm = recording(tmp_path_factory.mktemp("align"), 0.008)
    return diagnose_arm(table, arm)


def test_a_torque_column_ahead_of_the_motion_is_named_with_its_size(shifted_result) -> None:
    s = arm_summary(shifted_result)
    # within a third of the 10 ms sampling period: a friction step is stamped on the sample grid
    assert s["torque_time_offset_s"] == pytest.approx(0.008, abs=0.0034), s["verdict"]
    assert "ms ahead of the motion columns" in s["verdict"]


def test_friction_is_fitted_on_the_realigned_torques(shifted_result) -> None:
    fits = {f.joint: f.params for f in shifted_result.findings if f.joint is not None}
    for j in range(2):
        assert fits[j]["coulomb_friction"] == pytest.approx(COULOMB[j], rel=0.1), fits
        assert fits[j].get("viscous_friction", 0.0) == pytest.approx(VISCOUS[j], rel=0.25), fits


def test_aligned_columns_name_no_offset(tmp_path) -> None:
    table, arm = recording(tmp_path, 0.0)
    v, a = accelerations(table)
    tau_nominal = inverse_dynamics(arm, table.q, v, a)
    train = table.t < 18.0
    noise = [float(np.std(np.diff(table.tau[:, j] - tau_nominal[:, j])) / math.sqrt(2)) for j in range(2)]
    assert torque_time_offset(table.t, table.tau, tau_nominal, v, train, [0, 1], noise) is None
