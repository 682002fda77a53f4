"""Renders the calibration checkerboard as the eye-in-hand camera sees it (simulator side).

Each square is a polygon whose edges are subdivided before projection, so the lens distortion
bends them as it bends real edges; polygons are filled with 1/16 px vertex precision, their
edges 8-connected (no partial coverage: OpenCV smooths LINE_AA edges only in 8-bit images,
and the board used to be drawn LINE_AA into float planes, which gave these very pixels). Real
projective geometry through cv2.projectPoints with the camera's intrinsics and distortion.
`board_patch` gives the board alone as a label per pixel (0 outside, one for the light and
one for the dark squares: albedo and coverage through `board_levels`) for the camera
simulator to composite into its scene (firmware_sim/camera/service.py: defocus, lighting
and sensor noise of the marker scene); `render_board` puts it on a plain background with a
simple blur and noise for offline tests.
"""
from __future__ import annotations

from functools import lru_cache

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


@lru_cache(maxsize=4)
def _polygons(s: float, squares: tuple[int, int], m: float) -> tuple[np.ndarray, np.ndarray]:
    """The outline (margin `m`) then the dark squares (side `s`) of a board of `squares`, in the
    board frame: all vertices (N, 3) and each polygon's vertex count."""
    nx, ny = squares
    # Board frame origin is the first inner corner: squares start one square before it.
    polys = [_outline(-s - m, -s - m, (nx - 1) * s + m, (ny - 1) * s + m)]
    polys += [_outline((i - 1) * s, (j - 1) * s, i * s, j * s)
              for j in range(ny) for i in range(nx) if (i + j) % 2 == 0]
    vertices = np.vstack(polys)
    vertices.flags.writeable = False
    return vertices, np.array([len(p) for p in polys])


@lru_cache(maxsize=8)
def _codes(light: float, dark: float) -> tuple[int, int, float]:
    """board_patch's labels for the light and the dark squares and the step that makes each
    label's albedo label * step, exactly in float32 (0.85 and 0.05: 17 and 1 steps of 0.05),
    so that the renderer blurs the labels with the step in its filter (no float albedo plane:
    renderer._scale_of); (1, 2, 0.0) when no such labels exist (then the renderer looks the
    albedo up in its table)."""
    L, D = np.float32(light), np.float32(dark)
    for dark_code in range(1, 256):
        step = np.float32(D / np.float32(dark_code))
        light_code = int(round(float(L / step))) if step > 0 else 0
        if (np.float32(dark_code) * step == D and 0 < light_code < 256 and light_code != dark_code
                and np.float32(light_code) * step == L):
            return light_code, dark_code, float(step)
    return 1, 2, 0.0


def board_levels(board: BoardConfig) -> np.ndarray:
    """The albedo of each of board_patch's labels, indexed by label (float32; label 0 covers
    nothing, labels no square has are never drawn)."""
    light, dark, step = _codes(board.light, board.dark)
    if step > 0:
        return np.arange(max(light, dark) + 1, dtype=np.float32) * np.float32(step)
    levels = np.zeros(3, np.float32)
    levels[light], levels[dark] = board.light, board.dark
    return levels


def board_patch(camera_T_board: np.ndarray, board: BoardConfig, K: np.ndarray, dist: np.ndarray,
                size: tuple[int, int], margin: int = 2) -> tuple[np.ndarray, np.ndarray, tuple[int, int]] | None:
    """The board alone in the (distorted) image, only over the pixels it covers: a uint8 label
    per pixel (the light or the dark squares', 0 where it is not), its labels' albedos
    (board_levels) and the patch's top-left pixel (x, y) in the image of `size` (w, h), with
    `margin` px of zeros around the pixels the vertices fall in (within the image); None when
    the camera sees its back, it is behind the camera or out of view. All vertices go through one
    cv2.projectPoints call and the polygons are drawn into the patch (why: per square, the
    calls and full-frame planes cost ~12 ms a frame; two float planes of the patch, ~2 ms); a
    vertex shift by whole pixels moves the rasterisation exactly, so the patch is the
    full-frame drawing's pixels."""
    width, height = size
    R, t = camera_T_board[:3, :3], camera_T_board[:3, 3]
    if (R @ np.array([0.0, 0.0, -1.0]))[2] > 0:    # the camera sees the board's back
        return None
    vertices, counts = _polygons(board.square, tuple(board.squares), board.margin)
    ends = np.cumsum(counts)
    near = (vertices @ R.T + t)[:, 2] > 0.01
    drawn = np.logical_and.reduceat(near, ends - counts).tolist()      # each polygon's vertices all in front
    if not drawn[0]:
        return None
    px, _ = cv2.projectPoints(vertices, cv2.Rodrigues(R)[0], t, K, dist)
    pts = np.round(px.reshape(-1, 2) * (1 << SHIFT)).astype(np.int64)
    outline = pts[:ends[0]]
    lo = np.maximum(np.floor_divide(outline.min(0), 1 << SHIFT) - margin, 0)
    hi = np.minimum(np.floor_divide(outline.max(0), 1 << SHIFT) + 1 + margin, (width, height))
    if (hi <= lo).any():
        return None
    pts = (pts - (lo << SHIFT)).astype(np.int32)
    light, dark, _ = _codes(board.light, board.dark)
    labels = np.zeros((int(hi[1] - lo[1]), int(hi[0] - lo[0])), np.uint8)
    cv2.fillPoly(labels, [pts[:ends[0]]], light, lineType=cv2.LINE_8, shift=SHIFT)
    squares = [pts[start:end] for start, end, ok in zip(ends[:-1], ends[1:], drawn[1:]) if ok]
    if squares:
        cv2.fillPoly(labels, squares, dark, lineType=cv2.LINE_8, shift=SHIFT)
    return labels, board_levels(board), (int(lo[0]), int(lo[1]))


def board_layer(camera_T_board: np.ndarray, board: BoardConfig, K: np.ndarray, dist: np.ndarray,
                size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray] | None:
    """board_patch over the whole image as planes: albedo premultiplied by coverage and the
    coverage (alpha), float32 (height, width); None as board_patch. Composited over any
    background, it is the board in that scene."""
    patch = board_patch(camera_T_board, board, K, dist, size)
    if patch is None:
        return None
    labels, levels, (x, y) = patch
    width, height = size
    albedo, alpha = np.zeros((height, width), np.float32), np.zeros((height, width), np.float32)
    h, w = labels.shape
    albedo[y:y + h, x:x + w] = levels[labels]
    alpha[y:y + h, x:x + w] = labels > 0
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
