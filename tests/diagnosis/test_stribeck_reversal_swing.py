"""Stiction on a slow ramp back and forth whose running level is most of its static level
(issue 31: the concealed bench's slow ramps named such Stribeck friction "Coulomb friction").

At 0.0108 rad/s a Stribeck law of 23.5 N m fading above 0.035 rad/s runs at 21.4 N m: its
breakaway peaks stand 2 N m above a Coulomb law's, and the joint sticks and slips along the
whole run, so the breakaway screen (stick_slip.py) sees no excess over its control windows.
The reversals' swing does differ, and replays of a Stribeck law fitted on it explain the
held-out torque better than the Coulomb law's (stribeck_replay.py). Coulomb and viscous
friction on the same joint and motion must stay what they are.
"""
from __future__ import annotations

from spacearm.offline.diagnosis.analysis import diagnose
# the slow ramps of the reversal-window tests (each joint its own speed and period), on joint 2
from tests.diagnosis.test_stiction_reversal_windows import BED, recorded as recorded_on

JOINT = 1


def recorded(seed: int, **effect):
    return recorded_on(seed, JOINT, **effect)


def first_on_joint(result):
    return next((f for f in result.findings if f.fit.channel == "tau" and f.fit.index == JOINT), None)


def test_stiction_mostly_running_at_a_slow_ramp_is_named_and_sized():
    result = diagnose(recorded(11, stribeck_friction=23.5, stribeck_velocity=0.025), BED)
    print(result.verdict)
    first = first_on_joint(result)
    assert first is not None and first is result.findings[0] and first.fit.effects == ("stribeck",), result.verdict
    assert abs(first.params["stribeck_friction"] - 23.5) <= 0.15 * 23.5, result.verdict
    assert first.stderr["stribeck_friction"] > 0.0


def test_coulomb_friction_on_the_same_ramp_stays_coulomb():
    result = diagnose(recorded(12, coulomb_friction=19.5), BED)
    print(result.verdict)
    first = first_on_joint(result)
    assert first is not None and "stribeck" not in first.fit.effects, result.verdict


def test_viscous_friction_on_the_same_ramp_is_not_named_stiction():
    result = diagnose(recorded(13, viscous_friction=19.5 / 0.0108), BED)
    print(result.verdict)
    first = first_on_joint(result)
    assert first is not None and "stribeck" not in first.fit.effects, result.verdict
