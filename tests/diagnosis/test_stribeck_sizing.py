"""Stiction between point-to-point moves with dwells (issue 31: Stribeck levels named 40-75 %
low on the concealed bench's new trajectory families). The linear fit puts the level low (a
lower level with a slower decay fits the smeared slips), and the breakaway level that
corrects it (breakaway.py) was never taken: the held-out 40 % of the recording holds fewer
than five starts. Taken, it needs its own decay speed, or the law runs far above the
recording's running friction.
"""
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
HOME = -math.pi / 2


def point_to_point(seconds: float = 32.0) -> Trajectory:
    """Smooth (cosine) moves at up to 0.05 rad/s between fixed targets, with 1-2 s dwells:
    six starts in the training rows, three in the held-out ones."""
    t = np.arange(0.0, seconds, DT)
    q, k, x = np.zeros(len(t)), 0, 0.0
    targets = [0.05, -0.02, 0.04, -0.03, 0.06, 0.0, 0.07, 0.01, -0.04, 0.03, -0.01, 0.05]
    for i, target in enumerate(targets * 3):
        move = max(int(abs(target - x) / 0.048 * math.pi / 2 / DT), 5)
        seg = np.r_[x + (target - x) * (0.5 - 0.5 * np.cos(np.linspace(0.0, math.pi, move))),
                    np.full(int((1.0 + 0.5 * (i % 3)) / DT), target)]
        q[k:k + len(seg)] = seg[: len(t) - k]
        k, x = k + len(seg), target
        if k >= len(t):
            break
    return Trajectory(t, (HOME + q)[:, None])


def recorded(traj: Trajectory, **effect):
    joints = [j.model_copy(update={"torque_noise": 0.5}) for j in NOMINAL.joints]
    joints[0] = joints[0].model_copy(update=effect)
    return record_direct(NOMINAL.model_copy(update={"joints": joints, "seed": 7}), traj, None, hold_cycles=0)


def _stiction(result):
    first = result.findings[0] if result.findings else None
    assert first is not None and first.fit.effects == ("stribeck",), result.verdict
    return first


def test_stiction_between_point_to_point_moves_is_sized_by_its_breakaway():
    result = diagnose(recorded(point_to_point(), stribeck_friction=48.0, stribeck_velocity=0.021), NOMINAL)
    print(result.verdict)
    first = _stiction(result)
    assert abs(first.params["stribeck_friction"] - 48.0) <= 0.15 * 48.0, result.verdict
    # the decay speed goes with the level: the running friction stays what the recording shows
    assert 0.5 * 0.021 <= first.params["stribeck_velocity"] <= 2.0 * 0.021, result.verdict


def test_coulomb_friction_between_point_to_point_moves_stays_coulomb():
    result = diagnose(recorded(point_to_point(), coulomb_friction=8.0), NOMINAL)
    print(result.verdict)
    first = result.findings[0]
    assert "stribeck" not in first.fit.effects, result.verdict
