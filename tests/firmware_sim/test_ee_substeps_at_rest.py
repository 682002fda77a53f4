"""EndEffectorModel.steps(h, n) takes one sub-step for a mechanism at rest (both speeds times h
zero): the same floats, bit for bit, as n sub-steps one at a time, whatever the grip and turns
(out of range, -0.0, NaN, integers)."""
from __future__ import annotations

import math

from hypothesis import given, settings, strategies as st

from spacearm.firmware_sim.plant import EndEffectorModel, EndEffectorParams

_VALUES = st.one_of(st.floats(allow_nan=True), st.sampled_from([0.0, -0.0, 1.0, 0, 1, 2, -1, math.nan, math.inf]))
_SPEEDS = st.one_of(st.sampled_from([0.0, -0.0, 1e-320, -1e-320]), st.floats(allow_nan=True))


def _one_at_a_time(grip, turns, grip_speed, screw_speed, h, n):
    """steps()' loop as it was: n sub-steps, each clamped."""
    for _ in range(n):
        grip = min(1.0, max(0.0, grip + grip_speed * h))
        turns = max(0.0, turns + screw_speed * h)
    return grip, turns


@settings(max_examples=500, deadline=None)
@given(grip=_VALUES, turns=_VALUES, grip_speed=_SPEEDS, screw_speed=_SPEEDS,
       h=st.one_of(st.sampled_from([0.0, 0.0002, 0.001, 1e-300]), st.floats(allow_nan=True)), n=st.integers(0, 12))
def test_steps_at_rest_are_the_sub_steps_one_at_a_time(grip, turns, grip_speed, screw_speed, h, n):
    ee = EndEffectorModel(EndEffectorParams(), grip=grip, grip_speed=grip_speed, turns=turns, screw_speed=screw_speed)
    ee.steps(h, n)
    expected = _one_at_a_time(grip, turns, grip_speed, screw_speed, h, n)
    assert repr((ee.grip, ee.turns)) == repr(expected)
    assert [type(v) for v in (ee.grip, ee.turns)] == [type(v) for v in expected]
