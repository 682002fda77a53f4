"""Identification solvers sharing one residual/Jacobian (`Problem`): LSE, weighted LM (MAP), EKF.

  lse   Gauss-Newton, unit weights, minimum-norm steps: the papers' least squares.
  lm    Levenberg-Marquardt on whitened residuals (per-configuration covariance or sigmas),
        optional Gaussian prior (x_prior, sigma_prior) -> MAP estimate.
  ekf   EKF of the vision paper, eqs. (11)-(17): random-walk state (the parameter errors),
        P <- P + Q, innovation z - h(x) with J evaluated at the current estimate, gain, update.
All return a `CalibrationResult`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from spacearm.controller.calibration.residuals import Problem

Array = NDArray[np.float64]


@dataclass
class CalibrationResult:
    method: str
    names: tuple[str, ...]        # full parameter names
    free: list[str]               # estimated ones, in covariance order
    x: Array                      # full estimate
    x_nominal: Array              # full nominal vector (errors = x - x_nominal)
    covariance: Array             # (len(free), len(free))
    residuals: Array              # (N, k) final unweighted residuals
    iterations: int
    status: str                   # converged | max_iterations | failed
    message: str
    elapsed: float

    @property
    def estimate(self) -> dict[str, float]:
        """Identified errors of the free parameters (estimate minus nominal), SI units."""
        idx = [self.names.index(n) for n in self.free]
        return {n: float(self.x[i] - self.x_nominal[i]) for n, i in zip(self.free, idx)}

    @property
    def std(self) -> dict[str, float]:
        return {n: float(np.sqrt(max(self.covariance[k, k], 0.0))) for k, n in enumerate(self.free)}

    @property
    def rms_residual(self) -> float:
        return float(np.sqrt(np.mean(self.residuals ** 2)))


def _whiten(r: Array, A: Array, W: Array | None) -> tuple[Array, Array]:
    if W is None:
        return r.reshape(-1), A.reshape(-1, A.shape[-1])
    rw = np.einsum("nij,nj->ni", W, r)
    Aw = np.einsum("nij,njp->nip", W, A)
    return rw.reshape(-1), Aw.reshape(-1, A.shape[-1])


def _eval(problem: Problem, x_free: Array, W: Array | None) -> tuple[Array, Array, Array]:
    r, A = problem.residual_and_jacobian(problem.full(x_free))
    A = A[:, :, problem.free_idx]
    rw, Aw = _whiten(r, A, W)
    return r, rw, Aw


def lse(problem: Problem, max_iter: int = 30, xtol: float = 1e-12,
        max_halvings: int = 30) -> CalibrationResult:
    """Gauss-Newton (minimum-norm steps for rank-deficient sets) with a backtracking line search.

    Plain Gauss-Newton overshoots on ill-conditioned or mis-modelled sets and then diverges; here
    a step that raises the cost is halved until it lowers it, and when no fraction of the step
    helps the fit stops with status "stalled" (never a silently worse estimate).
    """
    t0 = time.perf_counter()
    x = problem.x0[problem.free_idx].copy()
    status, msg = "max_iterations", f"no convergence in {max_iter} iterations"
    it = 0
    r, rw, Aw = _eval(problem, x, None)
    cost = float(rw @ rw)
    for it in range(1, max_iter + 1):
        dx, *_ = np.linalg.lstsq(Aw, rw, rcond=1e-10)
        step = 1.0
        for _ in range(max_halvings):
            r2, rw2, Aw2 = _eval(problem, x + step * dx, None)
            cost2 = float(rw2 @ rw2)
            if np.isfinite(cost2) and cost2 <= cost * (1 + 1e-12) + 1e-300:
                break
            step *= 0.5
        else:
            status, msg = "stalled", f"no decrease along the Gauss-Newton step at iteration {it}"
            break
        x = x + step * dx
        small = np.linalg.norm(step * dx) <= xtol * (1.0 + np.linalg.norm(x))
        flat = cost - cost2 <= 1e-12 * max(cost, 1e-300)
        r, rw, Aw, cost = r2, rw2, Aw2, cost2
        if small or (flat and step == 1.0):
            status, msg = "converged", f"step below {xtol:g} after {it} iterations"
            break
    dof = max(rw.size - Aw.shape[1], 1)
    s2 = float(rw @ rw) / dof
    cov = s2 * np.linalg.pinv(Aw.T @ Aw, rcond=1e-12)
    return CalibrationResult("lse", problem.names, list(problem.free), problem.full(x),
                             problem.nominal(), cov, r, it, status, msg,
                             time.perf_counter() - t0)


def lm(problem: Problem, x_prior: ArrayLike | None = None, sigma_prior: ArrayLike | None = None,
       max_iter: int = 50, ftol: float = 1e-12, xtol: float = 1e-12,
       weighted: bool = True) -> CalibrationResult:
    """Levenberg-Marquardt on whitened residuals with an optional Gaussian prior (MAP).

    x_prior is a full vector (default the problem's x0); sigma_prior (len(free),) may hold inf
    for "no prior" on some parameters.
    """
    t0 = time.perf_counter()
    W = problem.whitening() if weighted else None
    fi = problem.free_idx
    x = problem.x0[fi].copy()
    if sigma_prior is not None:
        xp = (problem.x0 if x_prior is None else np.asarray(x_prior, float))[fi]
        ip = 1.0 / np.broadcast_to(np.asarray(sigma_prior, float), x.shape)
    else:
        xp, ip = x.copy(), np.zeros_like(x)

    def cost_parts(x: Array) -> tuple[Array, Array, Array, float]:
        r, rw, Aw = _eval(problem, x, W)
        pr = ip * (xp - x)
        return r, rw, Aw, float(rw @ rw + pr @ pr)

    r, rw, Aw, cost = cost_parts(x)
    lam = 1e-3
    status, msg = "max_iterations", f"no convergence in {max_iter} iterations"
    it = 0
    for it in range(1, max_iter + 1):
        H = Aw.T @ Aw + np.diag(ip ** 2)
        g = Aw.T @ rw + ip ** 2 * (xp - x)
        # Marquardt scaling: damping proportional to the curvature of each parameter.
        D = np.diag(H).copy()
        D[D <= 0] = 1.0
        while True:
            try:
                dx = np.linalg.solve(H + lam * np.diag(D), g)
            except np.linalg.LinAlgError:
                dx = np.linalg.lstsq(H + lam * np.diag(D), g, rcond=None)[0]
            r2, rw2, Aw2, cost2 = cost_parts(x + dx)
            if cost2 <= cost:
                break
            lam *= 10.0
            if lam > 1e12:
                break
        if cost2 > cost:
            status, msg = "converged", "no further decrease"
            break
        improvement = cost - cost2
        x = x + dx
        r, rw, Aw, cost = r2, rw2, Aw2, cost2
        lam = max(lam / 10.0, 1e-12)
        if improvement <= ftol * max(cost, 1e-300) or np.linalg.norm(dx) <= xtol * (1 + np.linalg.norm(x)):
            status, msg = "converged", f"converged after {it} iterations"
            break
    H = Aw.T @ Aw + np.diag(ip ** 2)
    cov = np.linalg.pinv(H, rcond=1e-12)
    if W is None:
        dof = max(rw.size - Aw.shape[1], 1)
        cov *= float(rw @ rw) / dof
    return CalibrationResult("lm" if weighted else "lm_unweighted", problem.names,
                             list(problem.free), problem.full(x), problem.nominal(), cov, r, it,
                             status, msg, time.perf_counter() - t0)


@dataclass(frozen=True)
class EKFTuning:
    """P0 and Q diagonals (len(free)) and the measurement covariance R (k, k) or per config."""
    p0: Array
    q: Array
    R: Array

    @classmethod
    def paper(cls, problem: Problem, angle_std: float = np.radians(0.01), length_std: float = 1e-5,
              meas_sigma: ArrayLike | None = None) -> "EKFTuning":
        """The EKF paper's choice: P0 = Q = diag(0.01 deg^2 | 0.01 mm^2), R = diag(meas noise^2)."""
        var = np.array([(length_std if _is_length(n) else angle_std) ** 2 for n in problem.free])
        sig = problem.sigma if meas_sigma is None else meas_sigma
        R = np.diag(np.broadcast_to(np.asarray(sig, float), (problem.rows,)) ** 2)
        return cls(var, var.copy(), R)

    @classmethod
    def expected(cls, problem: Problem, angle: float = np.radians(0.5), length: float = 2e-3,
                 frame_length: float | None = None, frame_angle: float | None = None) -> "EKFTuning":
        """Default tuning: the prior P0 is the stated expected size of the errors (a constant
        parameter vector, so Q = 0), R the problem's own noise model (covariance or sigmas).

        The paper's P0 = Q = (0.01 deg | 0.01 mm)^2 is ~30x tighter than the errors it must find,
        so the filter cannot move far enough; with P0 from the expected errors the EKF is the
        sequential form of the MAP least-squares estimate (see `lm` with the same prior).
        """
        var = (expected_sigma(problem.free, angle, length, frame_length, frame_angle)) ** 2
        if getattr(problem, "cov", None) is not None:
            R = np.asarray(problem.cov, float)
        else:
            R = np.diag(np.broadcast_to(np.asarray(problem.sigma if problem.sigma is not None else 1.0,
                                                   float), (problem.rows,)) ** 2)
        return cls(var, np.zeros_like(var), R)

    @classmethod
    def by_name(cls, name: str, problem: Problem, **kw) -> "EKFTuning":
        """'expected' (default: prior from the expected error size) or 'paper' (the EKF paper's)."""
        if name == "paper":
            return cls.paper(problem)
        if name == "expected":
            return cls.expected(problem, **kw)
        raise ValueError(f"unknown EKF tuning {name!r} (expected, paper)")


def expected_sigma(names: list[str], angle: float, length: float, frame_length: float | None = None,
                   frame_angle: float | None = None) -> Array:
    """Per-parameter expected error size: D-H angles/lengths, frame/extra lengths/angles."""
    out = []
    for n in names:
        frame = not n.split("_")[0] in ("theta", "d", "a", "alpha", "beta")
        if _is_length(n):
            out.append(frame_length if (frame and frame_length is not None) else length)
        else:
            out.append(frame_angle if (frame and frame_angle is not None) else angle)
    return np.array(out, float)


def _is_length(name: str) -> bool:
    head, _, tail = name.rpartition("_")
    if head in ("theta", "d", "a", "alpha", "beta"):
        return head in ("d", "a")
    # frames (x, y, z), tool points (tx..), anchors (ax.., l0), plane offset (f)
    return tail in ("x", "y", "z", "f", "tx", "ty", "tz", "ax", "ay", "az", "l0")


def ekf(problem: Problem, tuning: EKFTuning, passes: int = 1) -> CalibrationResult:
    """Sequential EKF over the configurations (eqs. 11-17); `passes` > 1 re-sweeps the data."""
    t0 = time.perf_counter()
    fi = problem.free_idx
    x = problem.x0[fi].copy()
    Qn = np.diag(tuning.q)
    I = np.eye(len(x))
    per_config_R = tuning.R.ndim == 3
    status, msg = "converged", f"{passes} pass(es) over {problem.n_configs} configurations"
    x_prior = x.copy()
    for _ in range(passes):
        # Linearise all configurations once per pass (one batched call); within the pass the
        # innovation z - h(x) is r(x_lin) - J (x - x_lin) to first order, as in eq. (13).
        # Later passes restart from the prior (x0, P0) but linearise about the previous
        # estimate: the iterated EKF, so a pass is not frozen by the P collapsed in the last one.
        x_lin = x.copy()
        x = x_prior.copy()
        P = np.diag(tuning.p0).astype(float)
        r_all, A_all = problem.residual_and_jacobian(problem.full(x_lin))
        A_all = A_all[:, :, fi]
        for k in range(problem.n_configs):
            P = P + Qn                                                   # (12)
            J = A_all[k]
            h = r_all[k] - J @ (x - x_lin)                               # (13)
            R = tuning.R[k] if per_config_R else tuning.R
            S = J @ P @ J.T + R                                          # (14)
            K = np.linalg.solve(S, J @ P).T                              # (15)  (P, S symmetric)
            x = x + K @ h                                                # (16)
            IKJ = I - K @ J                                              # (17), Joseph form for
            P = IKJ @ P @ IKJ.T + K @ R @ K.T                            # numerical symmetry
    if not np.all(np.isfinite(x)):
        status, msg = "failed", "estimate not finite"
    r, _ = problem.residual_and_jacobian(problem.full(x))
    return CalibrationResult("ekf", problem.names, list(problem.free), problem.full(x),
                             problem.nominal(), P, r, passes * problem.n_configs, status, msg,
                             time.perf_counter() - t0)
