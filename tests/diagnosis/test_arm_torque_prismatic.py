"""The URDF path (`diagnose --urdf`) states a prismatic joint's findings in its own units:
a vertical lift (a linear axis) carrying an arm link has its friction in N, not N m."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from spacearm.offline.diagnosis.arm_torque import arm_summary, diagnose_arm, joint_kinds
from spacearm.offline.diagnosis.recording_io import RecordingTable
from spacearm.offline.diagnosis.rigid_body import inverse_dynamics, load_arm

LINK = '<link name="{0}"><inertial><origin xyz="{1}"/><mass value="{2}"/>' \
       '<inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>'
LIFT_ARM = f"""<robot name="lift_arm">
  <link name="base"/>
  {LINK.format("carriage", "0 0 0", 12.0)}
  {LINK.format("upper_arm", "0.3 0 0", 4.0)}
  <joint name="lift" type="prismatic"><parent link="base"/><child link="carriage"/><axis xyz="0 0 1"/>
    <limit lower="0" upper="0.5" effort="2000" velocity="0.3"/></joint>
  <joint name="shoulder" type="revolute"><parent link="carriage"/><child link="upper_arm"/><axis xyz="0 1 0"/>
    <origin xyz="0 0 0.1"/><limit lower="-2" upper="2" effort="100" velocity="1"/></joint>
</robot>
"""


def test_a_lift_is_prismatic_and_its_friction_is_in_newtons(tmp_path: Path) -> None:
    (tmp_path / "lift_arm.urdf").write_text(LIFT_ARM)
    arm = load_arm(tmp_path / "lift_arm.urdf", 2)
    assert joint_kinds(arm) == ["prismatic", "revolute"]
    dt = 0.01
    t = np.arange(0.0, 40.0, dt)
    lo, hi = arm.model.lowerPositionLimit, arm.model.upperPositionLimit
    q = np.repeat(((lo + hi) / 2)[None, :], len(t), axis=0)
    w = 2 * math.pi * 0.1
    q[:, 0] += 0.1 * np.sin(w * t)                         # the lift travels +-0.1 m
    dq = np.zeros_like(q)
    dq[:, 0] = 0.1 * w * np.cos(w * t)
    ddq = np.zeros_like(q)
    ddq[:, 0] = -0.1 * w * w * np.sin(w * t)
    tau = inverse_dynamics(arm, q, dq, ddq)
    tau[:, 0] += 30.0 * np.sign(dq[:, 0]) + np.random.default_rng(3).normal(0.0, 0.5, len(t))
    table = RecordingTable(t, q.copy(), q, dq, tau, np.zeros((len(t), 6)))
    s = arm_summary(diagnose_arm(table, arm))
    lift = next(f for f in s["findings"] if f["joint"] == 1)
    assert "coulomb" in lift["effects"] and abs(lift["parameters"]["coulomb_friction"] - 30.0) < 3.0
    assert "Coulomb friction" in lift["text"] and " N m" not in lift["text"], lift["text"]
    assert s["joints"][0]["kind"] == "prismatic" and s["joints"][0]["unit"] == "N"
