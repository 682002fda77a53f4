"""Coulomb friction on a slow ramp makes the joint stick at each reversal until the drive has
wound up the torque to break it free: a breakaway peak that Coulomb friction alone produces
through the servo. The linear candidates, functions of the frictionless nominal motion, see
that peak as a Stribeck bump, and Coulomb friction was named "stiction (Stribeck)" with
Coulomb beside it as equally good (concealed bench, slow ramps). The replay of each law sizes
and judges them as the joint really moves: Coulomb comes first."""
from __future__ import annotations

import math

import numpy as np
import pytest

from spacearm.offline.diagnosis.analysis import diagnose
from spacearm.offline.diagnosis.record import record_direct
from spacearm.offline.diagnosis.trajectory import Trajectory

from test_diagnosis import NOMINAL, Q_HOME, hidden

JOINT = 4


def slow_ramps(draw: int, seconds: float = 40.0) -> Trajectory:
    """Every joint back and forth at its own slow speed (triangle waves of 8-16 s, started a few
    centiradians from home), joint 5 at 0.011 rad/s."""
    rng = np.random.default_rng(draw)
    t = np.arange(0.0, seconds, 0.02)
    q = np.repeat((Q_HOME + rng.uniform(-0.03, 0.03, 6))[None, :], len(t), axis=0)
    for j in range(6):
        speed, period = rng.uniform(0.0036, 0.0144), rng.uniform(8.0, 16.0)
        speed = 0.011 if j == JOINT else speed
        q[:, j] += speed * period / 4 * 2 / math.pi * np.arcsin(np.sin(2 * math.pi * t / period))
    return Trajectory(t, q)


# draw 4: named stiction (Stribeck) 36.4 N m, fading above the running speed, before
@pytest.mark.parametrize("draw", [4])
def test_coulomb_friction_that_sticks_the_joint_at_reversals_is_named_coulomb_first(draw):
    table = record_direct(hidden(JOINT, coulomb_friction=36.0), slow_ramps(draw), None, hold_cycles=0)
    found = [f for f in diagnose(table, NOMINAL).findings if f.fit.index == JOINT]
    assert found and found[0].fit.effects == ("coulomb",), [f.text for f in found]
    assert abs(found[0].params["coulomb_friction"] - 36.0) <= 0.15 * 36.0
    # the recording moved at one speed: the other laws stay named beside it
    assert found[0].alternatives
