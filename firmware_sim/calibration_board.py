"""Renders the calibration checkerboard as the eye-in-hand camera sees it (simulator side).

Each square is a polygon whose edges are subdivided before projection, so the lens distortion
bends them as it bends real edges; polygons are filled anti-aliased with 1/16 px vertex
precision. Real projective geometry through cv2.projectPoints with the camera's intrinsics
and distortion. `board_layer` gives the board alone (albedo and coverage) for the camera
simulator to composite into its scene (firmware_sim/camera/service.py: defocus, lighting and
sensor noise of the marker scene); `render_board` puts it on a plain background with a simple
blur and noise for offline tests.
"""
from __future__ import annotations

import cv2
import numpy as np

from spacearm.base.config.board import BoardConfig

SHIFT = 4                 # fractional bits of the polygon vertices
EDGE_STEPS = 6            # segments per square edge


def _outline(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    t = np.linspace(0.0, 1.0, EDGE_STEPS, endpoint=False)
    edges = [np.stack([x0 + (x1 - x0) * t, np.full_like(t, y0)], 1),
             np.stack([np.full_like(t, x1), y0 + (y1 - y0) * t], 1),
             np.stack([x1 - (x1 - x0) * t, np.full_like(t, y1)], 1),
             np.stack([np.full_like(t, x0), y1 - (y1 - y0) * t], 1)]
    pts = np.concatenate(edges)
    return np.c_[pts, np.zeros(len(pts))]


def board_layer(camera_T_board: np.ndarray, board: BoardConfig, K: np.ndarray, dist: np.ndarray,
                size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray] | None:
    """The board alone in the (distorted) image: albedo premultiplied by coverage and the
    coverage (alpha), float32 (height, width); None when the camera sees its back or it is
    behind the camera. Composited over any background, it is the board in that scene."""
    width, height = size
    R, t = camera_T_board[:3, :3], camera_T_board[:3, 3]
    if (R @ np.array([0.0, 0.0, -1.0]))[2] > 0:    # the camera sees the board's back
        return None
    rvec = cv2.Rodrigues(R)[0]
    s, (nx, ny), m = board.square, board.squares, board.margin
    albedo = np.zeros((height, width), np.float32)
    alpha = np.zeros_like(albedo)

    def fill(canvas: np.ndarray, poly_board: np.ndarray, value: float) -> bool:
        cam = poly_board @ R.T + t
        if np.any(cam[:, 2] <= 0.01):
            return False
        px, _ = cv2.projectPoints(poly_board, rvec, t, K, dist)
        pts = np.round(px.reshape(-1, 2) * (1 << SHIFT)).astype(np.int32)
        cv2.fillPoly(canvas, [pts], float(value), lineType=cv2.LINE_AA, shift=SHIFT)
        return True

    # Board frame origin is the first inner corner: squares start one square before it.
    outline = _outline(-s - m, -s - m, (nx - 1) * s + m, (ny - 1) * s + m)
    if not fill(alpha, outline, 1.0):
        return None
    fill(albedo, outline, board.light)
    for j in range(ny):
        for i in range(nx):
            if (i + j) % 2 == 0:
                fill(albedo, _outline((i - 1) * s, (j - 1) * s, i * s, j * s), board.dark)
    return albedo, alpha


def render_board(camera_T_board: np.ndarray, board: BoardConfig, K: np.ndarray, dist: np.ndarray,
                 size: tuple[int, int], rng: np.random.Generator, background: float = 0.25,
                 blur_px: float = 0.8, noise: float = 2.0) -> np.ndarray:
    """8-bit mono image (height, width) of the board seen from `camera_T_board` (m), on a
    uniform background, with a Gaussian blur and additive noise (offline tests; the camera
    simulator composites `board_layer` into its own scene and sensor model)."""
    width, height = size
    canvas = np.full((height, width), background, np.float32)
    layer = board_layer(camera_T_board, board, K, dist, size)
    if layer is not None:
        albedo, alpha = layer
        canvas = albedo + (1.0 - alpha) * canvas
    return _finish(canvas * 255.0, blur_px, noise, rng)


def _finish(canvas: np.ndarray, blur_px: float, noise: float, rng: np.random.Generator) -> np.ndarray:
    if blur_px > 0:
        canvas = cv2.GaussianBlur(canvas, (0, 0), blur_px)
    if noise > 0:
        canvas = canvas + rng.normal(0.0, noise, canvas.shape).astype(np.float32)
    return np.clip(np.round(canvas), 0, 255).astype(np.uint8)
