"""A loose or elastic gear's period in one call (firmware_sim/two_mass.py, and its copy in the
compiled core) computes what the plant's sub-step path (drive_torque(), the servo,
_substep_two_mass(), advance_motor()) computes, bit for bit, on random plants and servo laws,
held or free."""
from __future__ import annotations

import math
import random

import pytest
from hypothesis import given, settings, strategies as st

from spacearm.firmware_sim import simcore
from spacearm.firmware_sim.joint_drive import SERVO_CSP, SERVO_OFF
from spacearm.firmware_sim.plant import JointParams
from spacearm.firmware_sim.two_mass import two_mass_period
from tests.firmware_sim.core_switch import needs_core
from tests.firmware_sim.test_simcore import _Law, _joint, _state, random_fields

finite = st.floats(-3.0, 3.0, allow_nan=False)


def _params(rng: random.Random, prismatic: bool, friction: bool, te: bool, play: bool, elastic: bool) -> JointParams:
    """A random joint with a loose gear (play), an elastic one, or both; a light link at times."""
    fields = random_fields(rng, prismatic, friction, te)
    fields.update(link_inertia=rng.choice([0.0, fields["link_inertia"]]),
                  backlash=rng.uniform(1e-5, 1e-2) if play or not elastic else 0.0,
                  joint_stiffness=rng.uniform(1e2, 1e6) if elastic else 0.0,
                  joint_damping=rng.choice([0.0, rng.uniform(0.0, 500.0)]))
    return JointParams(**fields)


@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), q=finite, qd=finite, q_end=finite,
       torque_ff=st.sampled_from([0.0, -0.0, 0.7, -1.3]), kind=st.sampled_from([SERVO_OFF, SERVO_CSP]),
       brake=st.booleans(), friction=st.booleans(), te=st.booleans(), prismatic=st.booleans(),
       play=st.booleans(), elastic=st.booleans(), substeps=st.integers(1, 20), periods=st.integers(1, 3))
def test_a_two_mass_period_in_one_call_is_the_sub_step_path(seed, q, qd, q_end, torque_ff, kind, brake, friction,
                                                            te, prismatic, play, elastic, substeps, periods):
    rng = random.Random(seed)
    params = _params(rng, prismatic, friction, te, play, elastic)
    amplitude = rng.choice([0.0, rng.uniform(-50.0, 50.0)])
    max_torque = rng.choice([math.inf, rng.uniform(0.1, 10.0)])
    fractions = [(k + 1) / substeps for k in range(substeps)]
    h = 0.02 / substeps
    external = rng.uniform(-1.0, 1.0)
    theta = q + rng.uniform(-1e-3, 1e-3)        # the motor off the link's position: the gear's play
    outcomes = []
    for whole in (True, False):
        joint = _joint(params, q, qd, 0.3, brake, amplitude, max_torque)
        joint.theta, joint.external_torque = theta, external
        law = _Law(kind, q, q_end, (q_end - q) / 0.02, torque_ff, joint)
        servo = joint.controller = law.servo        # one bound method: the plant checks it `is` the controller
        joint.period_servo = (servo, law.law) if whole else None
        try:
            for _ in range(periods):
                joint.substeps(fractions, h)
        except (OverflowError, ValueError) as exc:     # a gear too stiff for the step: both raise alike
            outcomes.append(type(exc))
        else:
            outcomes.append(_state(joint, law))
    assert outcomes[0] == outcomes[1]


def test_the_whole_period_is_taken_only_under_a_law_for_it(monkeypatch):
    """No period law (a drive ramping, halted, in profile position): the sub-step path runs."""
    from spacearm.firmware_sim import plant
    monkeypatch.setattr(simcore, "core", None)       # the Python period, to be counted
    calls = []
    real = plant.two_mass_period
    monkeypatch.setattr(plant, "two_mass_period", lambda *a: calls.append(a) or real(*a))
    joint = _joint(JointParams(backlash=1e-3), 0.0, 0.0, 0.0, False, 0.0, math.inf)
    law = _Law(SERVO_CSP, 0.0, 0.1, 5.0, 0.0, joint)
    servo = joint.controller = law.servo
    joint.period_servo = (servo, lambda: None)
    joint.substeps([0.5, 1.0], 0.01)
    assert not calls and joint.q != 0.0
    joint.period_servo = (servo, law.law)
    joint.substeps([0.5, 1.0], 0.01)
    assert len(calls) == 1


@needs_core
@settings(max_examples=300, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), q=finite, qd=finite, q_end=finite,
       torque_ff=st.sampled_from([0.0, -0.0, 0.7, -1.3]), kind=st.sampled_from([SERVO_OFF, SERVO_CSP]),
       brake=st.booleans(), friction=st.booleans(), te=st.booleans(), prismatic=st.booleans(),
       play=st.booleans(), elastic=st.booleans(), substeps=st.integers(1, 20))
def test_the_cores_two_mass_period_is_the_python_one(seed, q, qd, q_end, torque_ff, kind, brake, friction, te,
                                                     prismatic, play, elastic, substeps):
    """Including where the core leaves the period to Python (None): Python then raises or
    gives non-finite numbers, which repr() compares as they are."""
    rng = random.Random(seed)
    joint = _joint(_params(rng, prismatic, friction, te, play, elastic), q, qd, 0.3, brake,
                   rng.choice([0.0, rng.uniform(-50.0, 50.0)]), rng.choice([math.inf, rng.uniform(0.1, 10.0)]))
    fractions = [(k + 1) / substeps for k in range(substeps)]
    args = (fractions, kind, 0.02 / substeps, brake, rng.uniform(-1.0, 1.0), q, qd, q + rng.uniform(-1e-3, 1e-3),
            qd, 0.3, q, q_end, (q_end - q) / 0.02, torque_ff, joint._core_constants())
    out = simcore.core.two_mass_period(*args)
    try:
        expected = two_mass_period(*args)
    except (OverflowError, ValueError):
        assert out is None
        return
    if out is not None:
        assert repr(out) == repr(expected)
    else:       # left to Python only where a value is not finite
        assert not all(math.isfinite(x) for x in expected)
