"""Geometric Jacobian against central finite differences of FK."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from spacearm.base.kinematics import KinematicData, fk, fk_jacobian, jacobian, load_model
from kin_reference import ARM_DIR, numeric_jacobian



def _check(model, q, data=None):
    data = KinematicData(model) if data is None else data
    J = jacobian(model, data, q)
    Jn = numeric_jacobian(lambda x: fk(model, data, x), q)
    # Central differences with h = 1e-6: truncation ~ h^2 * reach, round-off ~ 1e-16 / h.
    np.testing.assert_allclose(J, Jn, atol=1e-8 * max(1.0, model.reach))


def test_jacobian_matches_finite_differences(arm, rng):
    model, data = arm
    for q in model.random_configurations(50, rng):
        _check(model, q, data)


def test_jacobian_with_beta_and_all_errors(arm, rng):
    """Nonzero Hayati beta on every joint (both conventions): the axis of joint i is z of the
    frame before Rz(theta_i), which for standard D-H already includes Ry(beta_{i-1})."""
    model, _ = arm
    m = model.with_errors(dtheta=rng.normal(0, 0.05, model.nq), dalpha=rng.normal(0, 0.05, model.nq),
                          da=rng.normal(0, 0.01, model.nq), dd=rng.normal(0, 0.01, model.nq),
                          dbeta=rng.uniform(0.05, 0.3, model.nq))
    data = KinematicData(m)
    for q in m.random_configurations(30, rng):
        _check(m, q, data)


def test_fk_jacobian_consistent(arm, rng):
    model, data = arm
    q = model.random_configurations(1, rng)[0]
    T, J = fk_jacobian(model, data, q)
    assert J.shape == (6, model.nq)
    np.testing.assert_allclose(T, fk(model, KinematicData(model), q))
    # angular rows are unit joint axes
    np.testing.assert_allclose(np.linalg.norm(J[3:], axis=0), 1.0)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-3.0, 3.0, allow_nan=False), min_size=6, max_size=6),
       st.floats(-0.3, 0.3), st.floats(-0.3, 0.3))
def test_property_laser_jacobian_any_beta(qs, beta2, beta6):
    m = load_model(ARM_DIR / "space_robot_6dof_laser.toml").with_errors(
        dbeta=[0.0, beta2, 0.0, 0.0, 0.0, beta6])
    _check(m, np.array(qs))
