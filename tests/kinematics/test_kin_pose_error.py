"""Rotation conversions and pose error metrics."""
from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from spacearm.base.kinematics import (matrix_to_rotvec, matrix_to_rpy, pose_errors_batch,
                                   position_error, rotation_error, rotvec_to_matrix,
                                   rpy_to_matrix, to_mm, twist_error)

vec3 = st.lists(st.floats(-1.0, 1.0, allow_nan=False), min_size=3, max_size=3)


@settings(max_examples=200, deadline=None)
@given(vec3, st.floats(0.0, math.pi))
def test_property_rotvec_roundtrip_and_scipy(axis, angle):
    axis = np.array(axis)
    if np.linalg.norm(axis) < 1e-3:
        axis = np.array([0.0, 0.0, 1.0])
    w = axis / np.linalg.norm(axis) * angle
    R = rotvec_to_matrix(w)
    np.testing.assert_allclose(R, Rotation.from_rotvec(w).as_matrix(), atol=1e-12)
    w2 = matrix_to_rotvec(R)
    np.testing.assert_allclose(rotvec_to_matrix(w2), R, atol=1e-12)
    assert abs(np.linalg.norm(w2) - angle) < 1e-9


def test_rotvec_near_pi_and_zero():
    for angle in (math.pi, math.pi - 1e-10, math.pi - 1e-5, 1e-12, 0.0):
        for axis in ([1, 0, 0], [0, 1, 0], [0, 0, 1], [1, -2, 3]):
            a = np.array(axis, float) / np.linalg.norm(axis)
            R = Rotation.from_rotvec(a * angle).as_matrix()
            w = matrix_to_rotvec(R)
            np.testing.assert_allclose(rotvec_to_matrix(w), R, atol=1e-12)
            assert abs(np.linalg.norm(w) - angle) < 1e-9


@settings(max_examples=200, deadline=None)
@given(st.floats(-math.pi, math.pi), st.floats(-1.5, 1.5), st.floats(-math.pi, math.pi))
def test_property_rpy_matches_scipy_extrinsic_xyz(roll, pitch, yaw):
    R = rpy_to_matrix([roll, pitch, yaw])
    # R = Rz(yaw) Ry(pitch) Rx(roll) is scipy's extrinsic "xyz".
    np.testing.assert_allclose(R, Rotation.from_euler("xyz", [roll, pitch, yaw]).as_matrix(),
                               atol=1e-12)
    np.testing.assert_allclose(rpy_to_matrix(matrix_to_rpy(R)), R, atol=1e-12)


def test_pose_errors():
    T1 = np.eye(4)
    T2 = np.eye(4)
    T2[:3, 3] = [0.003, 0.004, 0.0]
    T2[:3, :3] = rotvec_to_matrix([0.0, 0.0, 0.01])
    assert abs(position_error(T1, T2) - 0.005) < 1e-15
    assert abs(to_mm(position_error(T1, T2)) - 5.0) < 1e-12
    assert abs(rotation_error(T1, T2) - 0.01) < 1e-15
    e = twist_error(T2, T1)  # target T2 from current T1
    np.testing.assert_allclose(e, [0.003, 0.004, 0, 0, 0, 0.01], atol=1e-15)
    pos, ang = pose_errors_batch(np.stack([T1, T2]), np.stack([T2, T2]))
    np.testing.assert_allclose(pos, [0.005, 0.0], atol=1e-15)
    np.testing.assert_allclose(ang, [0.01, 0.0], atol=1e-15)
