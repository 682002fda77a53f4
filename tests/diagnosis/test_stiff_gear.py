"""A gear stiff enough that the drive does not ring (8e4 N m/rad on this test bed) still makes
the motor run ahead of the link by the deflection: a smooth torque term that a replay with the
stiffness reproduces sample by sample. It was fitted as a 169 N m "load" that moved the link,
dropped, and the joint reported as nothing (issue 31: elasticity missed at 6.8e4-2e5 N m/rad)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from spacearm.offline.diagnosis.analysis import diagnose
from spacearm.offline.diagnosis.record import record_direct
from spacearm.offline.diagnosis.trajectory import Trajectory

from test_diagnosis import NOMINAL, Q_HOME, hidden


def brisk(seconds: float = 30.0) -> Trajectory:
    """Joint 1 swings 0.1 rad once a second: enough torque through the gear to deflect it."""
    t = np.arange(0.0, seconds, 0.02)
    return Trajectory(t, Q_HOME + 0.1 * np.sin(2 * math.pi * t[:, None] / np.array([1.0, 6, 7, 8, 9, 10])))


def test_a_stiff_gear_is_named_as_elasticity_with_its_stiffness():
    result = diagnose(record_direct(hidden(0, joint_stiffness=8e4), brisk(), None, hold_cycles=0), NOMINAL)
    found = [f for f in result.findings if f.fit.index == 0]
    assert [f.fit.effects for f in found] == [("elasticity",)]
    assert found[0].params["joint_stiffness"] == pytest.approx(8e4, rel=0.10)
    assert found[0].params["joint_stiffness"] > 0.0
    tau = next(c for c in result.channels if c.name == "tau_1")
    assert tau.rms_after < 0.5 * tau.rms_before          # held-out torque error, per channel
    q = next(c for c in result.channels if c.name == "q_1")
    assert q.rms_after <= q.rms_before + q.noise           # and the link's position no worse


def test_backlash_on_the_same_motion_is_not_named_elasticity():
    result = diagnose(record_direct(hidden(0, backlash=2e-3), brisk(), None, hold_cycles=0), NOMINAL)
    effects = [e for f in result.findings if f.fit.index == 0 for e in f.fit.effects]
    assert "elasticity" not in effects
    assert "backlash" in effects


def test_no_effect_on_the_same_motion_is_not_named():
    result = diagnose(record_direct(hidden(), brisk(), None, hold_cycles=0), NOMINAL)
    assert result.findings == []
