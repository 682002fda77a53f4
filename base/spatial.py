"""Elementary homogeneous transforms and rotation conversions (SI units, radians).

rpy follows the arm files: R = Rz(yaw) Ry(pitch) Rx(roll) (roll-pitch-yaw about fixed axes).
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]


def rotx(angle: float) -> Array:
    """4x4 rotation about x."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1]])


def roty(angle: float) -> Array:
    """4x4 rotation about y."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0, s, 0], [0, 1.0, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1]])


def rotz(angle: float) -> Array:
    """4x4 rotation about z."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1.0, 0], [0, 0, 0, 1]])


def trans(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Array:
    """4x4 pure translation."""
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def inv_transform(T: ArrayLike) -> Array:
    """Inverse of a rigid 4x4 transform (R^T, -R^T p)."""
    T = np.asarray(T, dtype=float)
    out = np.eye(4)
    R = T[:3, :3]
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ T[:3, 3]
    return out


def rpy_to_matrix(rpy: ArrayLike) -> Array:
    """3x3 rotation R = Rz(yaw) Ry(pitch) Rx(roll) from (roll, pitch, yaw)."""
    r, p, y = (float(v) for v in rpy)
    return (rotz(y) @ roty(p) @ rotx(r))[:3, :3]


def matrix_to_rpy(R: ArrayLike) -> Array:
    """(roll, pitch, yaw) with R = Rz(yaw) Ry(pitch) Rx(roll); pitch in [-pi/2, pi/2].

    At pitch = +-pi/2 (gimbal lock) roll is set to 0 and yaw carries the rotation.
    """
    R = np.asarray(R, dtype=float)
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    if math.hypot(R[0, 0], R[1, 0]) < 1e-12:
        roll = 0.0
        yaw = math.atan2(-R[0, 1], R[1, 1])
    else:
        roll = math.atan2(R[2, 1], R[2, 2])
        yaw = math.atan2(R[1, 0], R[0, 0])
    return np.array([roll, pitch, yaw])


def xyz_rpy_to_transform(xyz: ArrayLike, rpy: ArrayLike) -> Array:
    """4x4 transform Trans(xyz) * Rz(yaw) Ry(pitch) Rx(roll)."""
    T = np.eye(4)
    T[:3, :3] = rpy_to_matrix(rpy)
    T[:3, 3] = np.asarray(xyz, dtype=float)
    return T


def rotvec_to_matrix(rotvec: ArrayLike) -> Array:
    """3x3 rotation from a rotation vector (axis * angle), Rodrigues' formula."""
    w = np.asarray(rotvec, dtype=float)
    angle = math.sqrt(float(w @ w))
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if angle < 1e-8:
        # Second-order series keeps orthogonality to ~1e-16 at these angles.
        return np.eye(3) + K + 0.5 * (K @ K)
    K /= angle
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)


def matrix_to_rotvec(R: ArrayLike) -> Array:
    """Rotation vector (axis * angle, angle in [0, pi]) of a 3x3 rotation matrix.

    Plain floats rather than numpy ops: this sits inside the IK loop.
    """
    R = np.asarray(R, dtype=float)
    r00, r01, r02 = float(R[0, 0]), float(R[0, 1]), float(R[0, 2])
    r10, r11, r12 = float(R[1, 0]), float(R[1, 1]), float(R[1, 2])
    r20, r21, r22 = float(R[2, 0]), float(R[2, 1]), float(R[2, 2])
    wx, wy, wz = 0.5 * (r21 - r12), 0.5 * (r02 - r20), 0.5 * (r10 - r01)
    s = math.sqrt(wx * wx + wy * wy + wz * wz)
    c = 0.5 * (r00 + r11 + r22 - 1.0)
    angle = math.atan2(s, c)
    if c > -0.7:
        # sin(angle) is well conditioned here; angle/sin -> 1 as angle -> 0.
        k = angle / s if s > 1e-15 else 1.0
        return np.array([wx * k, wy * k, wz * k])
    # Near pi the antisymmetric part vanishes: read the axis from the symmetric part,
    # (R + R^T)/2 = c I + (1 - c) k k^T, and take its sign from the antisymmetric part.
    one_c = 1.0 - c
    kk = np.array([[r00 - c, 0.5 * (r01 + r10), 0.5 * (r02 + r20)],
                   [0.5 * (r01 + r10), r11 - c, 0.5 * (r12 + r21)],
                   [0.5 * (r02 + r20), 0.5 * (r12 + r21), r22 - c]]) / one_c
    i = int(np.argmax(np.diag(kk)))
    axis = kk[i] / math.sqrt(max(kk[i, i], 1e-300))
    if axis @ np.array([wx, wy, wz]) < 0.0:
        axis = -axis
    return axis * angle


def cross3(a: list[float], b: list[float]) -> list[float]:
    """a x b of two 3-vectors given as floats, in scalars: np.cross's products and differences in
    the same order (the same bits), without its ~30-40 us of axis handling a call (issue 35: the
    impedance mode's and the contact world's per-cycle and per-sub-step cross products)."""
    ax, ay, az = a
    bx, by, bz = b
    return [ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx]
