"""Pinhole + Brown-Conrady camera model (OpenCV conventions), SI units.

Camera frame: x right, y down, z along the optical axis. Pixel (0, 0) is the centre of the
top-left pixel.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from spacearm.base.vision.config import CameraConfig


@dataclass(frozen=True)
class CameraModel:
    width: int
    height: int
    K: np.ndarray            # 3x3
    dist: np.ndarray         # (5,) k1 k2 p1 p2 k3
    pixel_size: float        # m

    @classmethod
    def from_config(cls, cfg: CameraConfig) -> "CameraModel":
        i = cfg.intrinsics
        K = np.array([[i.fx, 0.0, i.cx], [0.0, i.fy, i.cy], [0.0, 0.0, 1.0]])
        return cls(cfg.sensor.width, cfg.sensor.height, K, np.asarray(i.distortion, float),
                   cfg.sensor.pixel_size)

    @property
    def focal_px(self) -> float:
        return float(self.K[0, 0])

    def distort_normalized(self, xy: np.ndarray) -> np.ndarray:
        """Ideal normalised (x/z, y/z) -> distorted normalised coordinates, (N, 2)."""
        k1, k2, p1, p2, k3 = self.dist
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.stack([xd, yd], axis=-1)

    def normalized_to_pixels(self, xy: np.ndarray, distort: bool = True) -> np.ndarray:
        if distort:
            xy = self.distort_normalized(xy)
        K = self.K
        return np.stack([K[0, 0] * xy[..., 0] + K[0, 2], K[1, 1] * xy[..., 1] + K[1, 2]], axis=-1)

    def project(self, points_cam: np.ndarray, distort: bool = True) -> np.ndarray:
        """Project (N, 3) camera-frame points (z > 0) to (N, 2) pixels."""
        p = np.asarray(points_cam, float)
        return self.normalized_to_pixels(p[..., :2] / p[..., 2:3], distort)

    def undistort_pixels(self, uv: np.ndarray) -> np.ndarray:
        """Distorted pixels (N, 2) -> ideal normalised coordinates (N, 2)."""
        uv = np.asarray(uv, np.float64).reshape(-1, 1, 2)
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 1e-10)
        out = cv2.undistortPoints(uv, self.K, self.dist, None, None, None, crit)
        return out.reshape(-1, 2)

    def in_image(self, uv: np.ndarray, margin: float = 0.0) -> np.ndarray:
        uv = np.asarray(uv)
        return ((uv[..., 0] >= margin - 0.5) & (uv[..., 0] <= self.width - 0.5 - margin)
                & (uv[..., 1] >= margin - 0.5) & (uv[..., 1] <= self.height - 0.5 - margin))
