"""Stribeck friction on a slow ramp at one speed runs at one level, like Coulomb friction, and
differs from it only in the breakaway at the few reversals. Where that breakaway stands within
the noise the recording cannot separate the two laws, and the honest answer says so with the
experiment that would (issue 31: such ramps were named Coulomb or viscous friction alone)."""
from __future__ import annotations

import math

import numpy as np

from spacearm.offline.diagnosis.analysis import diagnose, ideal_sensors
from spacearm.offline.diagnosis.direct_sim import simulate
from spacearm.offline.diagnosis.record import record_direct
from spacearm.offline.diagnosis.separable import separation
from spacearm.offline.diagnosis.trajectory import Trajectory

from test_diagnosis import NOMINAL, Q_HOME, hidden

JOINT = 3
STRIBECK = {"stribeck_friction": 12.0, "stribeck_velocity": 0.08}


def motion(speed: float, period: float, seconds: float = 40.0, wave: str = "triangle") -> Trajectory:
    """Joint 4 alone back and forth; a triangle wave runs at one speed, a sine through all below its peak."""
    t = np.arange(0.0, seconds, 0.02)
    q = np.repeat(Q_HOME[None, :], len(t), axis=0)
    amplitude = speed * period / 4 if wave == "triangle" else speed * period / (2 * math.pi)
    phase = 2 * math.pi * t / period
    q[:, JOINT] += amplitude * (2 / math.pi * np.arcsin(np.sin(phase)) if wave == "triangle" else np.sin(phase))
    return Trajectory(t, q)


def coulomb_at_running_level(speed: float):
    """The nominal plant with the Coulomb friction the Stribeck law runs at, at `speed`."""
    joints = list(NOMINAL.joints)
    level = STRIBECK["stribeck_friction"] * math.exp(-(speed / STRIBECK["stribeck_velocity"]) ** 2)
    joints[JOINT] = joints[JOINT].model_copy(update={"coulomb_friction": joints[JOINT].coulomb_friction + level})
    return NOMINAL.model_copy(update={"joints": joints})


def truth():
    return hidden(JOINT, **STRIBECK)


def quiet_truth():
    joints = list(NOMINAL.joints)
    joints[JOINT] = joints[JOINT].model_copy(update=STRIBECK)
    return NOMINAL.model_copy(update={"joints": joints})


def test_a_one_speed_ramp_names_friction_and_says_stribeck_is_not_separable_with_the_experiment():
    table = record_direct(truth(), motion(0.004, 12.0), None, hold_cycles=0)
    found = [f for f in diagnose(table, NOMINAL).findings if f.fit.index == JOINT]
    assert len(found) == 1
    assert set(found[0].fit.effects) <= {"coulomb", "viscous", "stribeck"}
    said = [a for a in found[0].alternatives if "Stribeck" in a] + ([found[0].text] if "stribeck" in found[0].fit.effects
                                                                     else [])
    assert said, found[0].alternatives
    if "stribeck" not in found[0].fit.effects:
        assert "not separable" in said[0] and "experiment" in said[0]


def velocity(table) -> np.ndarray:
    return simulate(ideal_sensors(NOMINAL), table.q_cmd, table.dt, q0=table.q[0], joints=[JOINT]).dq[:, 0]


def test_the_one_speed_ramp_does_not_separate_stribeck_from_its_running_coulomb_level():
    table = record_direct(truth(), motion(0.004, 12.0), None, hold_cycles=0)
    sep = separation(table, quiet_truth(), coulomb_at_running_level(0.004), JOINT, velocity(table), 0.5)
    assert not sep.separable, sep


def test_speeds_through_the_decay_separate_them():
    table = record_direct(truth(), motion(0.1, 8.0, wave="sine"), None, hold_cycles=0)
    sep = separation(table, quiet_truth(), coulomb_at_running_level(0.004), JOINT, velocity(table), 0.5)
    assert sep.separable and sep.rms_gain > 0.3, sep
