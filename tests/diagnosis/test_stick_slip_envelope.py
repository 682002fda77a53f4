"""Stiction that drives stick-slip along a slow ramp's whole run (issue 31: the concealed
bench's slow ramps named 27 N m of stiction fading above 0.013 rad/s at a 0.011 rad/s ramp
"viscous friction, or Coulomb", development seed 5402).

Row by row the three laws explain the running level alike and the true law's replay, out of
phase with the recorded slips, scores worse than the Coulomb law's; the envelope of the
torque's swing about its running mean tells them apart (stick_slip_envelope.py). Coulomb
and viscous friction on the same ramp drive no stick-slip and must stay what they are
(test_stribeck_reversal_swing.py holds those).
"""
from __future__ import annotations

from spacearm.offline.diagnosis.analysis import diagnose
# the slow ramps of the reversal-window tests; joint 2 runs at 0.0108 rad/s
from tests.diagnosis.test_stiction_reversal_windows import BED, recorded

JOINT = 1


def test_stiction_that_drives_stick_slip_on_a_slow_ramp_is_named_and_sized():
    result = diagnose(recorded(21, JOINT, stribeck_friction=27.1, stribeck_velocity=0.013), BED)
    print(result.verdict)
    first = next((f for f in result.findings if f.fit.channel == "tau" and f.fit.index == JOINT), None)
    assert first is not None and first.fit.effects == ("stribeck",), result.verdict
    assert abs(first.params["stribeck_friction"] - 27.1) <= 0.15 * 27.1, result.verdict
    assert abs(first.params["stribeck_friction"] - 27.1) <= 1.96 * first.stderr["stribeck_friction"] or \
        abs(first.params["stribeck_friction"] - 27.1) <= 0.05 * 27.1, result.verdict
