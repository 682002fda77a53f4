"""camera_T_marker from the four identified circle centres (ORU paper eq. 5-12 use RPnP).

OpenCV solvers, each optionally refined by Levenberg-Marquardt on the reprojection error:
- "sqpnp": SQPnP (globally optimal, any number >= 3 of points, planar or not). Default.
- "epnp": EPnP (closed form; poor with only 4 points, kept for the comparison).
- "ap3p": AP3P on the three plate circles (up to four solutions), the rod circle picks the
  one with the smallest reprojection error: the same idea as the paper's RPnP (P3P
  polynomials of point triples, choose by reprojection error).
- "iterative": OpenCV's DLT/LM.
IPPE is not offered: it needs four or more coplanar points and our marker has three (the
fourth sits on the rod, which is what gives the tilt sensitivity).

Points are passed undistorted and normalised (identity camera matrix), so the solvers and the
refinement work on ideal pinhole rays; `reprojection_rms` is converted back to pixels with
the focal length.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

SOLVERS = ("sqpnp", "epnp", "ap3p", "iterative")
_EYE = np.eye(3)
_NODIST = np.zeros(5)


@dataclass(frozen=True)
class PnpResult:
    camera_T_marker: np.ndarray      # 4x4
    rms_px: float                    # reprojection rms, px
    residuals_px: np.ndarray         # (N,) per-point reprojection error, px


def _to_T(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = np.ravel(tvec)
    return T


def reprojection_px(T: np.ndarray, points: np.ndarray, xy: np.ndarray, focal_px: float) -> np.ndarray:
    pc = points @ T[:3, :3].T + T[:3, 3]
    if (pc[:, 2] <= 1e-6).any():
        return np.full(len(points), np.inf)
    return np.linalg.norm(pc[:, :2] / pc[:, 2:3] - xy, axis=1) * focal_px


def solve_pnp(points: np.ndarray, xy: np.ndarray, focal_px: float, solver: str = "sqpnp",
              refine: bool = True, guess: np.ndarray | None = None) -> PnpResult | None:
    """points (N, 3) marker frame, xy (N, 2) ideal normalised image coordinates. None if the
    solver found no pose in front of the camera."""
    if solver not in SOLVERS:
        raise ValueError(f"unknown PnP solver {solver!r} (known: {', '.join(SOLVERS)})")
    obj = np.ascontiguousarray(points, np.float64).reshape(-1, 1, 3)
    img = np.ascontiguousarray(xy, np.float64).reshape(-1, 1, 2)
    candidates: list[np.ndarray] = []
    if guess is not None:
        candidates.append(np.asarray(guess, float))
    elif solver == "ap3p":
        n, rvecs, tvecs = cv2.solveP3P(obj[:3], img[:3], _EYE, _NODIST, flags=cv2.SOLVEPNP_AP3P)
        candidates += [_to_T(r, t) for r, t in zip(rvecs, tvecs)]
    else:
        flag = {"sqpnp": cv2.SOLVEPNP_SQPNP, "epnp": cv2.SOLVEPNP_EPNP,
                "iterative": cv2.SOLVEPNP_ITERATIVE}[solver]
        try:
            ok, rvec, tvec = cv2.solvePnP(obj, img, _EYE, _NODIST, flags=flag)
        except cv2.error:
            ok = False
        if ok:
            candidates.append(_to_T(rvec, tvec))
    best: PnpResult | None = None
    for T in candidates:
        if refine:
            rvec, tvec = cv2.Rodrigues(T[:3, :3])[0], T[:3, 3].reshape(3, 1).copy()
            crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 1e-12)
            rvec, tvec = cv2.solvePnPRefineLM(obj, img, _EYE, _NODIST, rvec, tvec, crit)
            T = _to_T(rvec, tvec)
        res = reprojection_px(T, points, xy, focal_px)
        rms = float(np.sqrt(np.mean(res ** 2)))
        if np.isfinite(rms) and (best is None or rms < best.rms_px):
            best = PnpResult(T, rms, res)
    return best
