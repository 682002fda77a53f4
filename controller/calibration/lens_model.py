"""The camera's pose from its image of a checkerboard (PnP), with the camera's lens model off.

A pose estimate solves for the pose whose projection, through the camera's *stated* intrinsics,
best matches the detected corners. When the real lens differs (focal lengths off by fractions
f_x, f_y, principal point off by c_x, c_y in normalised image units, radial distortion
k_1 r^2 + k_2 r^4 not removed), every corner's normalised image point (u, v) is displaced by

    du = f_x u + c_x + u (k_1 r^2 + k_2 r^4),   dv = f_y v + c_y + v (k_1 r^2 + k_2 r^4),

and the estimate moves by the least-squares pose change that explains those displacements over
the corners in view: dpose = (J^T J)^-1 J^T D e with J the corners' image Jacobian. The bias so
depends on the view: how far off-axis the board sits, its tilt, which of its corners are in the
image. A distortion is invisible to a frame or D-H term, which moves every view alike; views at
the edge of the image (FR3: the two 55-degree views) carry most of it. First order in e: lens
errors of a few per cent move a pose by millimetres, the second-order term by micrometres.

LensModel adds these terms to BoardScaleModel (the board's pitch per axis); extra parameters
<prefix>_scale_x, _scale_y, then <prefix>_<term> for each lens term.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from spacearm.controller.calibration.measurement_models import BoardScaleModel, PoseModel

Array = NDArray[np.float64]
LENS_TERMS = ("fx", "fy", "cx", "cy", "k1", "k2")
MIN_CORNERS = 6      # fewer corners in view: no pose, no bias modelled


def board_corners(pitch: float, nx: int, ny: int, sign: tuple[float, float] = (1.0, 1.0)) -> Array:
    """(nx * ny, 3) inner corners of a checkerboard in its own frame (m), the origin a corner,
    the grid running along sign[0] * x and sign[1] * y."""
    gx, gy = np.meshgrid(sign[0] * pitch * np.arange(1, nx + 1), sign[1] * pitch * np.arange(1, ny + 1))
    return np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)


def _displacement(u: Array, v: Array, term: str) -> tuple[Array, Array]:
    r2 = u * u + v * v
    zero, one = np.zeros_like(u), np.ones_like(u)
    return {"fx": (u, zero), "fy": (zero, v), "cx": (one, zero), "cy": (zero, one),
            "k1": (u * r2, v * r2), "k2": (u * r2 * r2, v * r2 * r2)}[term]


def pnp_bias(T: Array, corners: Array, half_fov: tuple[float, float], terms: tuple[str, ...]) -> tuple[Array, Array]:
    """Per view (board_T_cam T, (N, 4, 4)): d(estimated pose)/d(lens term) as board-frame
    (position; rotation vector) rows (N, 6, len(terms)), and the corners in view (N,)."""
    R, p = T[:, :3, :3], T[:, :3, 3]
    X = np.einsum("nji,mj->nmi", R, corners) - np.einsum("nji,nj->ni", R, p)[:, None, :]   # camera frame
    z = X[..., 2]
    z_safe = np.where(z > 1e-6, z, 1.0)
    u, v = X[..., 0] / z_safe, X[..., 1] / z_safe
    seen = (z > 1e-6) & (np.abs(u) < half_fov[0]) & (np.abs(v) < half_fov[1])
    zero = np.zeros_like(z)
    du = np.stack([1 / z_safe, zero, -u / z_safe], -1)
    dv = np.stack([zero, 1 / z_safe, -v / z_safe], -1)
    # A camera-frame motion (rotation w, translation t) of the board moves a corner by w x X + t.
    J = np.concatenate([np.concatenate([np.cross(X, du), du], -1), np.concatenate([np.cross(X, dv), dv], -1)], 1)
    D = np.stack([np.concatenate(_displacement(u, v, t), axis=1) for t in terms], -1)
    w = np.concatenate([seen, seen], axis=1)[..., None].astype(float)
    JtJ = np.einsum("nki,nkj->nij", J * w, J) + 1e-12 * np.eye(6)
    move = np.linalg.solve(JtJ, np.einsum("nki,nkj->nij", J * w, D))    # board in the camera frame
    count = seen.sum(axis=1)
    move[count < MIN_CORNERS] = 0.0
    # The camera in the board frame moves the other way: position -R t, rotation -R w.
    out = np.empty((len(T), 6, len(terms)))
    out[:, :3] = -R @ move[:, 3:]
    out[:, 3:] = -R @ move[:, :3]
    return out, count


def _rotations(w: Array) -> Array:
    """Rotation matrices (N, 3, 3) of rotation vectors (N, 3) (Rodrigues)."""
    th = np.linalg.norm(w, axis=1)
    K = np.zeros((len(w), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    K -= np.swapaxes(K, 1, 2)
    big = th > 1e-9
    ts = np.where(big, th, 1.0)
    a = np.where(big, np.sin(ts) / ts, 1.0)
    b = np.where(big, (1 - np.cos(ts)) / ts ** 2, 0.5)
    return np.eye(3) + a[:, None, None] * K + b[:, None, None] * (K @ K)


@dataclass(frozen=True)
class LensModel(BoardScaleModel):
    """BoardScaleModel plus the camera's lens terms (`lens`, a subset of LENS_TERMS), for a board
    with these `corners` (board frame, m) seen by a camera whose image spans |u| < half_fov[0],
    |v| < half_fov[1] in normalised coordinates (tan of the half field of view)."""
    corners: Array = field(default_factory=lambda: np.zeros((0, 3)), compare=False)
    half_fov: tuple[float, float] = (1.0, 1.0)
    lens: tuple[str, ...] = ("fx", "fy", "cx", "cy", "k1")

    def __post_init__(self) -> None:
        unknown = set(self.lens) - set(LENS_TERMS)
        if unknown:
            raise ValueError(f"unknown lens terms {sorted(unknown)} (known: {', '.join(LENS_TERMS)})")

    @property
    def extra_names(self) -> tuple[str, ...]:
        return super().extra_names + tuple(f"{self.prefix}_{t}" for t in self.lens)

    @property
    def extra_nominal(self) -> Array:
        return np.zeros(len(self.extra_names))

    @property
    def board(self) -> BoardScaleModel:
        return BoardScaleModel(prefix=self.prefix)

    def _shifted(self, T: Array, e: Array) -> tuple[Array, Array]:
        """The pose estimate (N, 4, 4) and its derivative wrt the lens terms (N, 6, L)."""
        B, _ = pnp_bias(T, self.corners, self.half_fov, self.lens)
        out = self.board.predict(T, e[:2])
        d = B @ e[2:]
        out[:, :3, 3] += d[:, :3]
        out[:, :3, :3] = _rotations(d[:, 3:]) @ out[:, :3, :3]
        return out, B

    def predict(self, T: Array, e: Array) -> Array:
        return self._shifted(T, e)[0]

    def residual(self, T: Array, Jt: Array, e: Array, measured: Array) -> tuple[Array, Array, Array]:
        # The arm's Jacobian is the board model's: the lens bias changes with the pose only at second order.
        _, A, A_board = self.board.residual(T, Jt, e[:2], measured)
        P, B = self._shifted(T, e)
        r = PoseModel().residual(P, Jt, e, measured)[0]
        return r, A, np.concatenate([A_board, B], axis=2)
