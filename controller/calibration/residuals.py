"""Residual types and the calibration problem (parameters + data + weights) shared by all solvers.

Residual convention: r = measured - predicted, and A = d(predicted)/d(params), so a
Gauss-Newton step solves A dx ~= r. Residual kinds:

  pose      6 rows per configuration: (p_meas - p; log(R_meas R^T)) in the world frame
  position  3 rows per configuration
  plane     1 row: laser distance from the tool origin along tool +z to the plane n.p + f = 0,
            h = -(n.p_s + f) / (n.b_l)  (laser-ranger paper eq. 10), plane n, f identified too.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from spacearm.controller.calibration.errormodel import ErrorModel

Array = NDArray[np.float64]
ROWS = {"pose": 6, "position": 3, "plane": 1}
PLANE_KINDS = ("nx", "ny", "nz", "f")


@dataclass(frozen=True)
class PlaneTarget:
    """Measured plane n.p + f = 0 in the world frame (n not normalised: eq. (15) as written)."""
    normal: tuple[float, float, float]
    offset: float
    prefix: str = "plane"

    @property
    def names(self) -> list[str]:
        return [f"{self.prefix}_{k}" for k in PLANE_KINDS]

    @property
    def values(self) -> Array:
        return np.array([*self.normal, self.offset], float)


def rotvec_batch(R: Array) -> Array:
    """Rotation vectors of a stack of rotation matrices (N, 3, 3) -> (N, 3)."""
    w = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], -1)
    s = 0.5 * np.linalg.norm(w, axis=-1)
    c = 0.5 * (np.trace(R, axis1=1, axis2=2) - 1.0)
    ang = np.arctan2(s, c)
    # angle/sin(angle) -> 1 at 0; near pi the residuals of a calibration are never that large.
    k = np.where(s > 1e-12, ang / np.maximum(s, 1e-300), 1.0)
    return 0.5 * w * k[:, None]


def free_indices(names: tuple[str, ...], free: list[str]) -> NDArray[np.int_]:
    """Positions of the free parameters in the full vector; KeyError naming unknown ones."""
    lookup = {n: i for i, n in enumerate(names)}
    unknown = [n for n in free if n not in lookup]
    if unknown:
        raise KeyError(f"unknown parameters: {unknown}")
    return np.array([lookup[n] for n in free], dtype=int)


def laser_distance(T: Array, n: Array, f: float) -> Array:
    """Eq. (10): distance along tool +z from the tool origin to the plane, (N,)."""
    return -(T[:, :3, 3] @ n + f) / (T[:, :3, 2] @ n)


@dataclass
class Problem:
    """Everything a solver needs: error model, optional plane, data, free parameters, weights.

    Full parameter vector = model parameters followed by the plane's (nx, ny, nz, f).
    `cov` is the per-configuration measurement covariance (N, k, k) used by weighted solvers;
    `sigma` (k,) is the simpler diagonal alternative. Both None -> unit weights.
    """
    model: ErrorModel
    kind: str
    Q: Array
    measured: Array
    free: list[str]
    plane: PlaneTarget | None = None
    sigma: Array | None = None
    cov: Array | None = None
    x0: Array | None = None                 # full starting/nominal vector (default: nominal)
    names: tuple[str, ...] = field(init=False)
    free_idx: NDArray[np.int_] = field(init=False)

    def __post_init__(self) -> None:
        if self.kind not in ROWS:
            raise ValueError(f"kind must be one of {sorted(ROWS)}, got {self.kind!r}")
        if self.kind == "plane" and self.plane is None:
            raise ValueError("plane residuals need a PlaneTarget")
        self.Q = np.atleast_2d(np.asarray(self.Q, float))
        self.measured = np.asarray(self.measured, float)
        extra = self.plane.names if self.plane is not None else []
        self.names = tuple(self.model.names) + tuple(extra)
        self.free_idx = free_indices(self.names, self.free)
        if self.x0 is None:
            self.x0 = self.nominal()
        if self.measured.shape[0] != self.Q.shape[0]:
            raise ValueError("one measurement per configuration expected")

    # --------------------------------------------------------------------------- helpers
    @property
    def rows(self) -> int:
        return ROWS[self.kind]

    @property
    def n_configs(self) -> int:
        return self.Q.shape[0]

    def nominal(self) -> Array:
        extra = self.plane.values if self.plane is not None else np.zeros(0)
        return np.concatenate([self.model.nominal, extra])

    def full(self, x_free: ArrayLike, base: Array | None = None) -> Array:
        """Full vector with the free entries replaced by x_free."""
        out = (self.x0 if base is None else base).copy()
        out[self.free_idx] = x_free
        return out

    def subset(self, rows: ArrayLike) -> "Problem":
        """The same problem restricted to some configurations."""
        rows = np.asarray(rows)
        return Problem(self.model, self.kind, self.Q[rows], self.measured[rows], list(self.free),
                       self.plane, self.sigma, None if self.cov is None else self.cov[rows],
                       self.x0.copy())

    # ------------------------------------------------------------------------ evaluation
    def predict(self, x_full: ArrayLike, Q: Array | None = None) -> Array:
        """Predicted measurements for the full vector (N, ...) at Q (default: the data's)."""
        x_full = np.asarray(x_full, float)
        Q = self.Q if Q is None else Q
        T = self.model.poses(x_full[: self.model.n_params], Q)
        return self._from_poses(x_full, T)

    def _from_poses(self, x_full: Array, T: Array) -> Array:
        if self.kind == "pose":
            return T
        if self.kind == "position":
            return T[:, :3, 3]
        pv = x_full[self.model.n_params:]
        return laser_distance(T, pv[:3], pv[3])

    def residual_and_jacobian(self, x_full: ArrayLike, Q: Array | None = None,
                              measured: Array | None = None) -> tuple[Array, Array]:
        """r (N, k) = measured - predicted and A (N, k, P_full) = d predicted / d x_full."""
        x_full = np.asarray(x_full, float)
        Q = self.Q if Q is None else Q
        meas = self.measured if measured is None else measured
        npar = self.model.n_params
        T, Jt = self.model.poses_and_jacobian(x_full[:npar], Q)
        N = T.shape[0]
        P = len(self.names)
        A = np.zeros((N, self.rows, P))
        if self.kind == "pose":
            r = np.empty((N, 6))
            r[:, :3] = meas[:, :3, 3] - T[:, :3, 3]
            r[:, 3:] = rotvec_batch(meas[:, :3, :3] @ np.swapaxes(T[:, :3, :3], 1, 2))
            A[:, :, :npar] = Jt
        elif self.kind == "position":
            r = meas - T[:, :3, 3]
            A[:, :, :npar] = Jt[:, :3]
        else:
            pv = x_full[npar:]
            n, f = pv[:3], pv[3]
            ps, bl = T[:, :3, 3], T[:, :3, 2]
            nb = bl @ n
            h = -(ps @ n + f) / nb
            r = (meas - h)[:, None]
            # d bl = omega x bl; dh = -n.(dps + h dbl) / (n.bl)
            dbl = np.cross(np.swapaxes(Jt[:, 3:], 1, 2), bl[:, None, :])        # (N, P, 3)
            dps = np.swapaxes(Jt[:, :3], 1, 2)
            A[:, 0, :npar] = -((dps + h[:, None, None] * dbl) @ n) / nb[:, None]
            pj = ps + h[:, None] * bl
            A[:, 0, npar:npar + 3] = -pj / nb[:, None]
            A[:, 0, npar + 3] = -1.0 / nb
        return r, A

    def whitening(self) -> Array | None:
        """Per-configuration whitening matrices W (N, k, k) with W cov W^T = I, or None."""
        if self.cov is not None:
            L = np.linalg.cholesky(self.cov)
            return np.linalg.inv(L)
        if self.sigma is not None:
            s = np.broadcast_to(np.asarray(self.sigma, float), (self.rows,))
            return np.broadcast_to(np.diag(1.0 / s), (self.n_configs, self.rows, self.rows))
        return None
