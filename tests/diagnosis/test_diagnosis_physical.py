"""Physically admissible answers only (issue 31): a fit that needs a body no arm can have is
"the model is wrong here", never a finding, and a rigid-body correction that makes any joint
worse by more than its noise is not accepted as is. Torques are made with the Panda URDF's
own regressor (Pinocchio), so the truth is known joint by joint."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from spacearm.offline.diagnosis.arm_torque import accelerations, diagnose_arm
from spacearm.offline.diagnosis.physical import body_violations, parameter_violations
from spacearm.offline.diagnosis.recording_io import RecordingTable
from spacearm.offline.diagnosis.rigid_body import inverse_dynamics, load_arm, regressor

URDF = Path(__file__).resolve().parents[2] / "configs/urdf/panda/panda_arm_no_hand.urdf"
Q0 = np.array([0.0, -0.3, 0.0, -2.0, 0.0, 1.8, 0.8])
NOISE = 0.02


def _motion(seconds: float = 14.0, dt: float = 0.01) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(0.0, seconds, dt)
    q = np.repeat(Q0[None, :], len(t), axis=0)
    for j, (amp, period) in enumerate(((0.5, 7.0), (0.3, 5.3), (0.4, 6.1), (0.3, 4.7), (0.6, 3.9), (0.4, 4.3),
                                      (0.8, 3.1))):
        q[:, j] += amp * np.sin(2 * math.pi * t / period) + 0.3 * amp * np.sin(2 * math.pi * t / (0.37 * period))
    return t, q


def _table(t: np.ndarray, q: np.ndarray, tau: np.ndarray) -> RecordingTable:
    dq = np.gradient(q, t[1] - t[0], axis=0)
    tau = tau + np.random.default_rng(3).normal(0.0, NOISE, tau.shape)
    return RecordingTable(t, q.copy(), q, dq, tau, np.zeros((len(t), 6)))


def _with_last_link_change(delta: np.ndarray, only_joints: list[int] | None = None) -> tuple[RecordingTable, object]:
    """A recording whose torques differ from the URDF's by a change `delta` of the last link's
    ten dynamic parameters (on all joints, or only on `only_joints`: no body does that)."""
    arm = load_arm(URDF, 7)
    t, q = _motion()
    table = _table(t, q, np.zeros_like(q))
    v, a = accelerations(table)
    tau = inverse_dynamics(arm, q, v, a)
    extra = regressor(arm, q, v, a)[:, :, 60:70] @ delta
    if only_joints is not None:
        extra[:, [j for j in range(7) if j not in only_joints]] = 0.0
    return _table(t, q, tau + extra), arm


def _last_link(arm) -> np.ndarray:
    return np.asarray(arm.model.inertias[arm.model.njoints - 1].toDynamicParameters(), float)


def _masses_after(d, arm) -> list[float]:
    """Each link's mass with every rigid-body finding added to the URDF's."""
    masses = [float(arm.model.inertias[i + 1].mass) for i in range(arm.n)]
    for f in d.findings:
        if f.effects == ("payload",):
            masses[-1] += f.params["payload_mass"]
        for i, name in enumerate(arm.joint_names):
            masses[i] += f.params.get(f"mass_change_{name}", 0.0)
    return masses


def test_a_last_link_lighter_than_nothing_is_never_a_negative_payload():
    arm = load_arm(URDF, 7)
    # the recorded torques ask for the last link at -2x its mass: real bodies on the other links can give
    # the same torques (the last link's mass is identified only in combination with theirs), a payload cannot
    table, arm = _with_last_link_change(-3.0 * _last_link(arm))
    d = diagnose_arm(table, arm)
    assert all(m >= 0.0 for m in _masses_after(d, arm)), d.verdict
    assert not [f for f in d.findings if f.effects == ("payload",)], d.verdict


def test_torques_of_the_wrong_sign_are_a_wrong_model_not_a_finding():
    arm = load_arm(URDF, 7)
    t, q = _motion()
    table = _table(t, q, np.zeros_like(q))
    v, a = accelerations(table)
    # a sign error on every joint: only negative masses would explain it
    table.tau = -inverse_dynamics(arm, q, v, a) + np.random.default_rng(4).normal(0.0, NOISE, q.shape)
    d = diagnose_arm(table, arm)
    assert any("model is wrong here" in w for w in d.model_wrong), d.verdict
    assert "model is wrong here" in d.verdict
    assert not [f for f in d.findings if f.joint is None], d.verdict
    assert all(m >= 0.0 for m in _masses_after(d, arm))


def test_a_real_payload_is_still_named_with_its_mass():
    arm = load_arm(URDF, 7)
    nominal = _last_link(arm)
    com = nominal[1:4] / nominal[0]
    mass = 1.2
    # a point mass at the link's own centre of mass: mass, first moment and the parallel-axis inertia
    inertia = mass * (float(com @ com) * np.eye(3) - np.outer(com, com))
    delta = np.r_[mass, mass * com, inertia[0, 0], inertia[0, 1], inertia[1, 1], inertia[0, 2], inertia[1, 2],
                  inertia[2, 2]]
    table, arm = _with_last_link_change(delta)
    d = diagnose_arm(table, arm)
    payload = [f for f in d.findings if f.effects == ("payload",)]
    assert len(payload) == 1, d.verdict
    assert payload[0].params["payload_mass"] == pytest.approx(mass, rel=0.15)
    assert not d.model_wrong


def test_a_rigid_body_fit_that_makes_a_wrist_worse_is_not_accepted():
    arm = load_arm(URDF, 7)
    nominal = _last_link(arm)
    # a payload's torque shows on the shoulder only (a torque the recording's other joints lack): a
    # payload fit pooled over the joints explains the shoulder and puts torque on the wrist that is not there
    table, arm = _with_last_link_change(np.r_[2.0, 2.0 * nominal[1:4] / nominal[0], np.zeros(6)], only_joints=[1])
    d = diagnose_arm(table, arm)
    for j in d.joints:
        assert j.rms_fitted <= j.rms_nominal + j.noise, (j, d.verdict)
    assert not [f for f in d.findings if f.joint is None], d.verdict


def test_physical_checks_name_what_is_impossible():
    assert parameter_violations({"coulomb_friction": -0.1, "viscous_friction": 0.2}) == ["coulomb_friction -0.1 < 0"]
    assert parameter_violations({"joint_stiffness": 0.0})
    assert body_violations(np.r_[-1.0, np.zeros(9)])
    # a thin rod is a body; one principal moment larger than the other two together is not
    assert not body_violations(np.r_[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 1e-6])
    assert body_violations(np.r_[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.1, 0.0, 0.0, 0.1])
