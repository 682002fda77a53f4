"""Calibration checkerboard: its description, and camera_T_board from an image (OpenCV).

Corner detection uses OpenCV's sector-based detector (`findChessboardCornersSB`, sub-pixel
accurate and robust to blur), the pose `solvePnP` with the iterative (LM) solver seeded by
IPPE for a planar target. A failure (board not found, too few corners, bad reprojection) is
reported, never turned into a pose.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from spacearm.base.config.board import BoardConfig


class BoardNotFound(Exception):
    """No complete, consistent board in the image."""


@dataclass(frozen=True)
class BoardPose:
    camera_T_board: np.ndarray
    reprojection_rms: float      # px
    corners: np.ndarray          # (N, 2) detected, px


def _rotation_angle(R: np.ndarray) -> float:
    return float(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)))


def detect_corners(image: np.ndarray, board: BoardConfig) -> np.ndarray:
    """Inner corners (N, 2) in px, sub-pixel refined; raises BoardNotFound."""
    # Classic detector on a half-size image (fast), then sub-pixel refinement at full size.
    small = cv2.resize(image, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
    found, corners = cv2.findChessboardCorners(small, board.inner, flags=flags)
    if not found or corners is None:
        raise BoardNotFound("checkerboard not found in the image")
    corners = corners * 2.0
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    corners = cv2.cornerSubPix(image, corners.astype(np.float32), (7, 7), (-1, -1), criteria)
    return corners.reshape(-1, 2).astype(np.float64)


def _solve(obj: np.ndarray, corners: np.ndarray, K: np.ndarray, dist: np.ndarray) -> tuple[np.ndarray, float]:
    ok, rvec, tvec = cv2.solvePnP(obj, corners, K, dist, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise BoardNotFound("PnP failed")
    ok, rvec, tvec = cv2.solvePnP(obj, corners, K, dist, rvec, tvec, useExtrinsicGuess=True,
                                  flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise BoardNotFound("PnP refinement failed")
    projected, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
    rms = float(np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - corners) ** 2, axis=1))))
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.ravel()
    return T, rms


def board_pose(image: np.ndarray, board: BoardConfig, K: np.ndarray, dist: np.ndarray,
               predicted: np.ndarray | None = None, max_reprojection_px: float = 1.0) -> BoardPose:
    """camera_T_board from one image. A checkerboard looks the same turned by 180 deg, so the
    detector may number the corners from either end; with `predicted` (camera_T_board from the
    nominal model) the numbering that agrees with it is kept."""
    corners = detect_corners(image, board)
    obj = board.object_points()
    T, rms = _solve(obj, corners, K, dist)
    if predicted is not None and _rotation_angle(T[:3, :3].T @ predicted[:3, :3]) > np.pi / 2:
        corners = corners[::-1].copy()
        T, rms = _solve(obj, corners, K, dist)
    if rms > max_reprojection_px:
        raise BoardNotFound(f"board pose rejected: reprojection RMS {rms:.2f} px > {max_reprojection_px} px")
    return BoardPose(T, rms, corners)
