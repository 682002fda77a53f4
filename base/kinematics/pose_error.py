"""Pose error metrics shared by IK, calibration and tests.

Convention: errors are "target minus current" expressed in the base frame, so that a geometric
Jacobian step J dq = twist_error(T_target, T_current) moves the current pose toward the target.
Position in metres (format as mm at the edges with `to_mm`), orientation as a rotation-vector
angle in radians.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from spacearm.base.spatial import (matrix_to_rotvec, matrix_to_rpy,  # noqa: F401
                                              rotvec_to_matrix, rpy_to_matrix)

Array = NDArray[np.float64]


def position_error(T_target: ArrayLike, T_current: ArrayLike) -> float:
    """Euclidean distance between the two origins, m."""
    a = np.asarray(T_target)
    b = np.asarray(T_current)
    return float(np.linalg.norm(a[:3, 3] - b[:3, 3]))


def rotation_error(T_target: ArrayLike, T_current: ArrayLike) -> float:
    """Angle of the relative rotation R_target R_current^T, rad in [0, pi]."""
    a = np.asarray(T_target)
    b = np.asarray(T_current)
    return float(np.linalg.norm(matrix_to_rotvec(a[:3, :3] @ b[:3, :3].T)))


def twist_error(T_target: ArrayLike, T_current: ArrayLike) -> Array:
    """6-vector (p_target - p_current; log(R_target R_current^T)) in the base frame."""
    a = np.asarray(T_target)
    b = np.asarray(T_current)
    e = np.empty(6)
    e[:3] = a[:3, 3] - b[:3, 3]
    e[3:] = matrix_to_rotvec(a[:3, :3] @ b[:3, :3].T)
    return e


def pose_errors_batch(T_target: ArrayLike, T_current: ArrayLike) -> tuple[Array, Array]:
    """Position errors (N,) in m and rotation angles (N,) in rad for stacks of poses."""
    a = np.asarray(T_target, dtype=float)
    b = np.asarray(T_current, dtype=float)
    pos = np.linalg.norm(a[..., :3, 3] - b[..., :3, 3], axis=-1)
    R = a[..., :3, :3] @ np.swapaxes(b[..., :3, :3], -1, -2)
    w = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0],
                  R[..., 1, 0] - R[..., 0, 1]], axis=-1)
    # atan2(|sin|, cos) is accurate at both small angles and near pi (acos is not).
    ang = np.arctan2(0.5 * np.linalg.norm(w, axis=-1),
                     0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0))
    return pos, ang


def to_mm(metres: float) -> float:
    """Metres to millimetres, for reports and logs."""
    return metres * 1000.0


def wrap_angle(x: ArrayLike) -> Array:
    """Wrap angles to [-pi, pi)."""
    return (np.asarray(x, dtype=float) + math.pi) % (2.0 * math.pi) - math.pi
