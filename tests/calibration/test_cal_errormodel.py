"""Error model: agrees with the kinematics core, analytic Jacobians match finite differences."""
from __future__ import annotations

import numpy as np
import pytest

from spacearm.controller.calibration import Problem, rotvec_batch
from spacearm.controller.calibration.residuals import laser_distance
from spacearm.base.kinematics import fk_batch


@pytest.mark.parametrize("which", ["laser_em", "ssrms_em"])
def test_nominal_poses_equal_kinematics_core(which, request):
    em = request.getfixturevalue(which)
    Q = em.kin.random_configurations(50, np.random.default_rng(0))
    np.testing.assert_allclose(em.poses(em.nominal, Q), fk_batch(em.kin, Q), atol=1e-12)


@pytest.mark.parametrize("which", ["laser_em", "ssrms_em"])
def test_to_kinematics_reproduces_perturbed_model(which, request):
    em = request.getfixturevalue(which)
    rng = np.random.default_rng(1)
    p = em.nominal + rng.normal(0.0, 5e-3, em.n_params)   # every parameter incl. frames, beta
    Q = em.kin.random_configurations(30, rng)
    np.testing.assert_allclose(em.poses(p, Q), fk_batch(em.to_kinematics(p), Q), atol=1e-12)


@pytest.mark.parametrize("which", ["laser_em", "ssrms_em"])
def test_pose_jacobian_matches_finite_differences(which, request):
    em = request.getfixturevalue(which)
    rng = np.random.default_rng(2)
    p = em.nominal + rng.normal(0.0, 1e-2, em.n_params)
    Q = em.kin.random_configurations(4, rng)
    T, J = em.poses_and_jacobian(p, Q)
    h = 1e-6
    for j in range(em.n_params):
        dp = np.zeros(em.n_params)
        dp[j] = h
        Tp, Tm = em.poses(p + dp, Q), em.poses(p - dp, Q)
        dpos = (Tp[:, :3, 3] - Tm[:, :3, 3]) / (2 * h)
        drot = (rotvec_batch(Tp[:, :3, :3] @ np.swapaxes(T[:, :3, :3], 1, 2))
                - rotvec_batch(Tm[:, :3, :3] @ np.swapaxes(T[:, :3, :3], 1, 2))) / (2 * h)
        np.testing.assert_allclose(J[:, :3, j], dpos, atol=1e-7, err_msg=em.names[j])
        np.testing.assert_allclose(J[:, 3:, j], drot, atol=1e-7, err_msg=em.names[j])


def _fd_check(pr, x, rng, tol):
    meas = pr.predict(x)          # residual zero: A is then exactly -dr/dx
    r, A = pr.residual_and_jacobian(x, measured=meas)
    h = 1e-6
    for j in range(len(x)):
        dx = np.zeros(len(x))
        dx[j] = h
        rp, _ = pr.residual_and_jacobian(x + dx, measured=meas)
        rm, _ = pr.residual_and_jacobian(x - dx, measured=meas)
        fd = -(rp - rm) / (2 * h)
        np.testing.assert_allclose(A[:, :, j], fd, atol=tol * max(1.0, np.abs(fd).max()),
                                   err_msg=pr.names[j])


def test_plane_distance_jacobian_matches_finite_differences(laser_em, paper_plane, laser_setup):
    from spacearm.controller.calibration.study_laser import candidates
    Q = candidates(laser_setup, 6, np.random.default_rng(3))
    pr = Problem(laser_em, "plane", Q, np.zeros(len(Q)), [], plane=paper_plane)
    x = pr.nominal() + np.random.default_rng(4).normal(0, 1e-3, len(pr.names))
    _fd_check(pr, x, None, 1e-6)


@pytest.mark.parametrize("kind", ["pose", "position"])
def test_pose_and_position_residual_jacobians(ssrms_em, kind):
    rng = np.random.default_rng(5)
    Q = ssrms_em.kin.random_configurations(3, rng)
    meas = np.zeros((3, 4, 4)) if kind == "pose" else np.zeros((3, 3))
    pr = Problem(ssrms_em, kind, Q, meas, [])
    _fd_check(pr, pr.nominal() + rng.normal(0, 1e-3, len(pr.names)), rng, 1e-6)


def test_laser_distance_eq10_hits_the_plane(paper_plane):
    T = np.eye(4)[None].repeat(2, 0)
    T[0, :3, 3] = (0.0, 0.0, 1.0)
    T[1, :3, :3] = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0.0]])  # beam along -y
    n, f = np.array(paper_plane.normal), paper_plane.offset
    h = laser_distance(T, n, f)
    spots = T[:, :3, 3] + h[:, None] * T[:, :3, 2]
    np.testing.assert_allclose(spots @ n + f, 0.0, atol=1e-12)
    assert h[0] == pytest.approx((0.69 - 4.6) / 4.6)
