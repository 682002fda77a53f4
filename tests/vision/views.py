"""Viewing geometry for the vision tests and bench: camera_T_marker from a distance, a tilt of
the marker away from the optical axis and where the marker sits in the image; pose errors."""
from __future__ import annotations

import numpy as np

from spacearm.base.spatial import inv_transform, matrix_to_rotvec, xyz_rpy_to_transform

# the marker's z axis points at the camera: camera z = -marker z
_FACING = xyz_rpy_to_transform((0.0, 0.0, 0.0), (np.pi, 0.0, 0.0))[:3, :3]


def view(distance: float, tilt: float = 0.0, azimuth: float = 0.0,
         offset: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """camera_T_marker: marker centre `distance` (m) along the optical axis (plus a lateral
    `offset` in m), the plate tilted by `tilt` (rad) about an in-plate axis at `azimuth`."""
    tilt_R = xyz_rpy_to_transform((0.0, 0.0, 0.0), (tilt * np.cos(azimuth), tilt * np.sin(azimuth), 0.0))[:3, :3]
    T = np.eye(4)
    T[:3, :3] = _FACING @ tilt_R
    T[:3, 3] = (offset[0], offset[1], distance)
    return T


def pose_error(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    """(position error m, rotation error rad) of T_est against T_true."""
    d = inv_transform(T_true) @ T_est
    return float(np.linalg.norm(d[:3, 3])), float(np.linalg.norm(matrix_to_rotvec(d[:3, :3])))
