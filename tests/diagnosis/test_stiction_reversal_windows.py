"""Stiction at the reversals of slow back-and-forth ramps on the six-joint test bed (issue 31:
the concealed bench's slow ramps named 34 N m of stiction "viscous friction, or Coulomb").

The breakaway peaks were taken over 3 s after each reversal: the largest of the running rows'
noise there stood as high as the breakaway, and a fit the held-out reversals confirmed was
rejected by a fixed ratio of two errors made of two reversals' peaks each. The window now ends
just after the recorded joint breaks free, and the held-out peaks must stand above the running
law's (and above every running law named beside it) by more than their scatter. Coulomb
friction on the same motion must not turn into "stiction" (stick_slip.py).
"""
from __future__ import annotations

import math

import numpy as np

from spacearm.offline.diagnosis.analysis import diagnose
from spacearm.offline.diagnosis.record import record_direct
from spacearm.offline.diagnosis.trajectory import Trajectory
from spacearm.firmware_sim.plant import load_plant_config

BED = load_plant_config("configs/plant/oru_testbed_nominal.toml")
DT = 0.02
# a slow-ramp case of the concealed bench's development seed: each joint its own speed and period
SPEEDS = (0.0085, 0.0108, 0.0085, 0.0043, 0.0108, 0.0073)      # rad/s
PERIODS = (8.6, 8.8, 15.4, 11.0, 10.3, 8.8)                    # s


def ramps(seconds: float = 40.0) -> Trajectory:
    t = np.arange(0.0, seconds, DT)
    home = np.array([j.initial_position for j in BED.joints])
    q = home + np.column_stack([s * p / 4 * (2 / math.pi) * np.arcsin(np.sin(2 * math.pi * t / p))
                                for s, p in zip(SPEEDS, PERIODS)])
    return Trajectory(t, q)


def recorded(seed: int, joint: int = 2, **effect):
    """The joint (index, default joint 3) with the effect; every joint's torque with 0.5 N m of
    sensor noise."""
    joints = [j.model_copy(update={"torque_noise": 0.5}) for j in BED.joints]
    joints[joint] = joints[joint].model_copy(update=effect)
    return record_direct(BED.model_copy(update={"joints": joints, "seed": seed}), ramps(), None, hold_cycles=0)


def test_stiction_at_slow_reversals_is_named_and_sized():
    result = diagnose(recorded(8, stribeck_friction=33.7, stribeck_velocity=0.0177), BED)
    print(result.verdict)
    first = result.findings[0] if result.findings else None
    assert first is not None and first.fit.index == 2 and first.fit.effects == ("stribeck",), result.verdict
    assert abs(first.params["stribeck_friction"] - 33.7) <= 0.15 * 33.7, result.verdict


def test_coulomb_friction_at_slow_reversals_is_not_named_stiction():
    result = diagnose(recorded(7, coulomb_friction=26.0), BED)
    print(result.verdict)
    first = result.findings[0] if result.findings else None
    assert first is not None and first.fit.index == 2 and "stribeck" not in first.fit.effects, result.verdict
