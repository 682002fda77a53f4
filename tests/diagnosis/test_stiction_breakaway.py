"""Stiction on a joint that runs at one speed between reversals (the concealed bench's slow
ramps): the running torque is the same constant for a Coulomb and a Stribeck law, and the
linear fits named it "Coulomb friction" (Stribeck was 4 of 17 on the held-out set). The
reversals separate them: the joint sticks until the drive reaches the static level, and the
recorded torque peaks above what a Coulomb replay does there (stick_slip.py)."""
from __future__ import annotations

import math

import numpy as np

from spacearm.offline.diagnosis.analysis import diagnose
from spacearm.offline.diagnosis.record import record_direct
from spacearm.offline.diagnosis.trajectory import Trajectory
from spacearm.firmware_sim.plant import load_plant_config

# the test bed's third joint alone (one joint replays six times faster than the arm)
_BED = load_plant_config("configs/plant/oru_testbed_nominal.toml")
NOMINAL = _BED.model_copy(update={"joints": [_BED.joints[2]]})
DT = 0.02


def slow_triangle(speed: float = 0.0084, period: float = 8.0, seconds: float = 40.0) -> Trajectory:
    """The joint back and forth at one slow speed (a triangle wave)."""
    t = np.arange(0.0, seconds, DT)
    q = -math.pi / 2 + speed * period / 4 * (2 / math.pi) * np.arcsin(np.sin(2 * math.pi * t / period))
    return Trajectory(t, q[:, None])


def recorded(**effect):
    joints = [j.model_copy(update={"torque_noise": 0.5}) for j in NOMINAL.joints]
    joints[0] = joints[0].model_copy(update=effect)
    return record_direct(NOMINAL.model_copy(update={"joints": joints, "seed": 7}), slow_triangle(), None,
                         hold_cycles=0)


def test_stiction_at_one_running_speed_is_named_by_its_breakaway_peaks():
    result = diagnose(recorded(stribeck_friction=9.0, stribeck_velocity=0.0106), NOMINAL)
    first = result.findings[0]
    print(result.verdict)
    assert first.fit.index == 0 and first.fit.effects == ("stribeck",), result.verdict
    assert first.params["stribeck_friction"] > 0.0 and first.params["stribeck_velocity"] > 0.0
    assert abs(first.params["stribeck_friction"] - 9.0) <= 0.25 * 9.0, first.params


def test_coulomb_friction_on_the_same_motion_stays_coulomb():
    result = diagnose(recorded(coulomb_friction=5.0), NOMINAL)
    first = result.findings[0]
    print(result.verdict)
    assert first.fit.index == 0 and "stribeck" not in first.fit.effects, result.verdict
