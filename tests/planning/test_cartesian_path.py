import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from spacearm.controller.planning.cartesian_path import CartesianLimits, CartesianPath, quintic

LIMITS = CartesianLimits(0.05, 0.1, 0.1, 0.2)


def pose(xyz, rotvec):
    T = np.eye(4)
    T[:3, 3] = xyz
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    return T


START = pose([0.5, 0.1, 0.3], [0.1, -0.2, 0.3])
GOAL = pose([0.7, -0.1, 0.2], [0.4, 0.1, -0.2])


def test_quintic_is_rest_to_rest():
    assert quintic(0.0) == (0.0, 0.0, 0.0)
    s, ds, dds = quintic(1.0)
    assert (s, ds, dds) == pytest.approx((1.0, 0.0, 0.0))


def test_path_hits_both_ends_and_stays_on_the_straight_line():
    path = CartesianPath.within_limits(START, GOAL, LIMITS)
    np.testing.assert_allclose(path.sample(0.0).pose, START, atol=1e-12)
    np.testing.assert_allclose(path.sample(path.duration).pose, GOAL, atol=1e-12)
    direction = (GOAL[:3, 3] - START[:3, 3]) / np.linalg.norm(GOAL[:3, 3] - START[:3, 3])
    for t in np.linspace(0, path.duration, 17):
        offset = path.sample(t).pose[:3, 3] - START[:3, 3]
        assert np.linalg.norm(offset - offset.dot(direction) * direction) < 1e-12


def test_velocities_match_finite_differences_and_respect_limits():
    path = CartesianPath.within_limits(START, GOAL, LIMITS)
    h = 1e-6
    for t in np.linspace(0.05, path.duration - 0.05, 11):
        a, b = path.sample(t - h), path.sample(t + h)
        v_fd = (b.pose[:3, 3] - a.pose[:3, 3]) / (2 * h)
        w_fd = Rotation.from_matrix(b.pose[:3, :3] @ a.pose[:3, :3].T).as_rotvec() / (2 * h)
        sample = path.sample(t)
        np.testing.assert_allclose(sample.linear_velocity, v_fd, atol=1e-7)
        np.testing.assert_allclose(sample.angular_velocity, w_fd, atol=1e-7)
        assert np.linalg.norm(sample.linear_velocity) <= LIMITS.linear_velocity * (1 + 1e-9)
        assert np.linalg.norm(sample.angular_velocity) <= LIMITS.angular_velocity * (1 + 1e-9)
