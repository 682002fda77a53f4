"""Forward kinematics against hand-worked poses, the papers' matrices and a naive reference."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from spacearm.base.kinematics import (KinematicData, dh_transform, fk, fk_batch, frames,
                                   load_model)
from kin_reference import ARM_DIR, Rx, Rz, Tx, Tz, ekf_paper_T, laser_paper_A, reference_fk


deg = math.pi / 180.0


def test_oru_home_pose_by_hand(models):
    """ORU Table 2 at the bracketed home angles (0, 90, -90, 0, -90, 0) deg.

    Worked by hand (modified D-H): T1 = I. T2 = Rx(-90)Rz(90)Tz(178.85): z2 = +y0, so the
    shoulder offset puts o2 at (0, 0.17885, 0) with x2 = -z0. T3 = Rx(-90)Rz(-90): x3 = +y0,
    z3 = -x0, o3 = o2. T4 = Tx(0.560)Tz(-0.174): o4 = o3 + 0.560 x3 - 0.174 z3
    = (0.174, 0.73885, 0). T5 = Tx(0.385)Rz(-90): o5 = (0.174, 1.12385, 0), x5 = +z0,
    z5 = -x0. T6 = Rx(-90): z6 = +y0, x6 = +z0. Tool Tz(0.46615): o = (0.174, 1.590, 0).
    The arm stretches along +y0 with the 174 mm elbow offset along +x0; tool axes
    x = z0, y = x0, z = y0.
    """
    m = models["oru_testbed_6dof"]
    T = fk(m, KinematicData(m), m.q_home)
    np.testing.assert_allclose(T[:3, 3], [0.174, 1.590, 0.0], atol=1e-12)
    np.testing.assert_allclose(T[:3, :3], [[0, 1, 0], [0, 0, 1], [1, 0, 0]], atol=1e-12)


def test_oru_home_product_of_elementary_transforms(models):
    """Same pose as the explicit product of the paper's rows (mm -> m)."""
    m = models["oru_testbed_6dof"]
    T = (Rz(0)
         @ Rx(-90 * deg) @ Rz(90 * deg) @ Tz(0.17885)
         @ Rx(-90 * deg) @ Rz(-90 * deg)
         @ Tx(0.560) @ Rz(0) @ Tz(-0.174)
         @ Tx(0.385) @ Rz(-90 * deg)
         @ Rx(-90 * deg) @ Rz(0)
         @ Tz(0.46615))
    np.testing.assert_allclose(fk(m, KinematicData(m), m.q_home), T, atol=1e-12)


def test_laser_home_pose_by_hand(models):
    """Laser Table 1 at q = 0 (theta = theta_n), standard D-H.

    A1 = Rz(90)Tz(0.5)Rx(-90): o1 = (0, 0, 0.5), x1 = +y0, z1 = -x0.
    A2 = Tx(1): o2 = (0, 1, 0.5). A3 = Rz(-90)Rx(90): x3 = +z0, z3 = -y0.
    A4 = Tz(-0.8)Rx(-90): o4 = o3 - 0.8 z3 = (0, 1.8, 0.5), z4 = -x0.
    A5 = Rz(180)Rx(90): x5 = -z0, y5 = -x0, z5 = +y0.
    A6 = Tz(0.4)Tx(-0.12): o6 = o5 + 0.4 z5 - 0.12 x5 = (0, 2.2, 0.62).
    """
    m = models["space_robot_6dof_laser"]
    T = fk(m, KinematicData(m), np.zeros(6))
    np.testing.assert_allclose(T[:3, 3], [0.0, 2.2, 0.62], atol=1e-12)
    np.testing.assert_allclose(T[:3, :3], [[0, -1, 0], [0, 0, 1], [-1, 0, 0]], atol=1e-12)


def test_ssrms_home_pose_by_hand(models):
    """EKF Table 2 at q = 0 with l0..l8 of the arm file.

    Base Rz(-90); joints 1-3 stack l0 along -x0, l1 along -z0, l2 along -x0; the booms l3, l5
    run along -z0, the side offsets l4, l6 along -x0, then l7 along -z0 and l8 along -x0:
    p = (-(0.6 + 0.5 + 0.1 + 0.1 + 0.6), 0, -(0.5 + 3.8 + 3.8 + 0.5)) = (-1.9, 0, -8.6).
    Tool Rx(90)Rz(90) after x7 = -y0, z7 = -x0 gives xE = -x0, yE = +y0, zE = -z0.
    """
    m = models["ssrms_7dof"]
    T = fk(m, KinematicData(m), np.zeros(7))
    np.testing.assert_allclose(T[:3, 3], [-1.9, 0.0, -8.6], atol=1e-12)
    np.testing.assert_allclose(T[:3, :3], np.diag([-1.0, 1.0, -1.0]), atol=1e-12)


def test_ssrms_matches_ekf_paper_eq1(models, rng):
    """Chain of the EKF paper's eq. (1) matrices (rows 0..7, E) equals our FK."""
    m = models["ssrms_7dof"]
    data = KinematicData(m)
    l = [0.6, 0.5, 0.5, 3.8, 0.1, 3.8, 0.1, 0.5, 0.6]
    rows = [  # a_{i-1}, alpha_{i-1} (deg), d_i, theta_i (deg) from Table 2
        (0, 90, l[0], 0), (0, 90, l[1], 0), (0, -90, l[2], -90), (l[3], 0, l[4], 0),
        (l[5], 0, l[6], 90), (0, 90, l[7], 0), (0, -90, l[8], 0)]
    for q in m.random_configurations(20, rng):
        T = ekf_paper_T(0, 0, 0, -90 * deg)
        for (a, al, d, th), qi in zip(rows, q):
            T = T @ ekf_paper_T(a, al * deg, d, th * deg + qi)
        T = T @ ekf_paper_T(0, 90 * deg, 0, 90 * deg)
        np.testing.assert_allclose(fk(m, data, q), T, atol=1e-12)


def test_laser_matches_paper_eq2_with_beta(models, rng):
    """Laser paper eq. (2) (D-H times Rot(y, beta)) with Table 2's errors applied."""
    m0 = models["space_robot_6dof_laser"]
    # Table 2 (mrad, mm), d2 and beta on joints 1, 3, 4, 5 not identifiable ("-").
    m = m0.with_errors(
        dtheta=np.array([-7.23, 0.52, 0.56, 0.36, -5.52, -0.34]) * 1e-3,
        dalpha=np.array([-3.22, 0.13, -2.23, 1.92, -4.83, 0.62]) * 1e-3,
        da=np.array([0.23, 1.94, 0.11, 0.18, 0.27, 0.47]) * 1e-3,
        dd=np.array([0.73, 0.0, 0.34, 1.35, 0.29, 0.85]) * 1e-3,
        dbeta=np.array([0, 1.45, 0, 0, 0, -3.36]) * 1e-3)
    assert list(m.beta_mask) == [False, True, False, False, False, True]
    data = KinematicData(m)
    for q in m.random_configurations(20, rng):
        T = np.eye(4)
        for i in range(6):
            T = T @ laser_paper_A(q[i] + m.theta_offset[i], m.alpha[i], m.a[i], m.d[i], m.beta[i])
        np.testing.assert_allclose(fk(m, data, q), T, atol=1e-12)
    # The errors must actually move the tool (Table 2 errors are mm-level).
    q = np.zeros(6)
    shift = np.linalg.norm(fk(m, data, q)[:3, 3] - fk(m0, KinematicData(m0), q)[:3, 3])
    assert 1e-3 < shift < 5e-2


def test_fk_matches_reference_all_arms_with_errors(arm, rng):
    model, _ = arm
    perturbed = model.with_errors(dtheta=rng.normal(0, 0.01, model.nq),
                                  dalpha=rng.normal(0, 0.01, model.nq),
                                  da=rng.normal(0, 1e-3, model.nq), dd=rng.normal(0, 1e-3, model.nq),
                                  dbeta=rng.normal(0, 0.01, model.nq))
    for m in (model, perturbed):
        data = KinematicData(m)
        for q in m.random_configurations(50, rng):
            np.testing.assert_allclose(fk(m, data, q), reference_fk(m, q), atol=1e-12)


def test_frames_are_the_dh_link_frames(arm, rng):
    model, data = arm
    q = model.random_configurations(1, rng)[0]
    F = frames(model, data, q)
    assert F.shape == (model.nq + 2, 4, 4)
    T = np.array(model.base)
    np.testing.assert_allclose(F[0], T)
    for i in range(model.nq):
        T = T @ dh_transform(model.convention, model.a[i], model.alpha[i], model.d[i],
                             q[i] + model.theta_offset[i], model.beta[i])
        np.testing.assert_allclose(F[i + 1], T, atol=1e-12)
    np.testing.assert_allclose(F[-1], T @ model.tool, atol=1e-12)


def test_batch_equals_single(arm, rng):
    model, data = arm
    Q = model.random_configurations(1000, rng)
    Tb = fk_batch(model, Q)
    Ts = np.array([fk(model, data, q) for q in Q])
    np.testing.assert_allclose(Tb, Ts, atol=1e-13)
    assert Tb.shape == (1000, 4, 4)
    np.testing.assert_array_equal(Tb[:, 3], np.tile([0.0, 0.0, 0.0, 1.0], (1000, 1)))


def test_batch_angles_at_half_angle_poles(models):
    """fk_batch uses tan(theta/2); theta = +-pi, 3 pi (tan -> inf) must still be exact."""
    m = models["ssrms_7dof"]
    data = KinematicData(m)
    specials = np.array([math.pi, -math.pi, 3 * math.pi, 0.0, math.pi / 2, -math.pi / 2, 5.2])
    Q = np.array([np.roll(specials, k) for k in range(7)]) - m.theta_offset
    np.testing.assert_allclose(fk_batch(m, Q), np.array([fk(m, data, q) for q in Q]), atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-6.0, 6.0, allow_nan=False), min_size=7, max_size=7))
def test_property_batch_single_reference_agree(qs):
    m = load_model(ARM_DIR / "ssrms_7dof.toml")
    q = np.array(qs)
    T1 = fk(m, KinematicData(m), q)
    np.testing.assert_allclose(fk_batch(m, q[None])[0], T1, atol=1e-12)
    np.testing.assert_allclose(reference_fk(m, q), T1, atol=1e-12)
    np.testing.assert_allclose(T1[:3, :3] @ T1[:3, :3].T, np.eye(3), atol=1e-12)


def test_model_is_immutable_and_errors_copy(models):
    m = models["oru_testbed_6dof"]
    with pytest.raises(ValueError):
        m.a[0] = 1.0
    m2 = m.with_errors(da=0.001)
    assert m2 is not m
    np.testing.assert_allclose(m2.a - m.a, 0.001)
    np.testing.assert_allclose(m.a, [0, 0, 0, 0.56, 0.385, 0])
    assert not np.allclose(m2.F, m.F)
