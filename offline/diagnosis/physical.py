"""Physical admissibility of a fitted model: what a real arm can have.

A fit that needs a mass below zero, an inertia that no body has, friction that pushes the
joint along or a gear with negative stiffness explains the data with something that cannot
exist: the model is wrong there (a scale error, a missing effect elsewhere), and that is what
the diagnosis must say, never the impossible value as a finding.

Rigid bodies: mass >= 0 and the rotational inertia about the centre of mass positive
definite with the triangle inequalities (each principal moment at most the sum of the other
two) - together the condition that the body's pseudo-inertia is positive semidefinite
(Wensing, Kim, Slotine, "Linear matrix inequalities for physically consistent inertial
parameter identification", RA-L 2017).
"""
from __future__ import annotations

import math

import numpy as np

# parameters that must not be negative (plant-file names, SI), and ones that must be positive
NON_NEGATIVE = ("coulomb_friction", "viscous_friction", "stribeck_friction", "stribeck_velocity", "backlash",
                "gravity_torque", "torque_limit_joint", "feedback_latency_cycles", "payload_total_mass")
POSITIVE = ("joint_stiffness",)
RELATIVE_TOLERANCE = 1e-9


def parameter_violations(params: dict[str, float]) -> list[str]:
    """Each parameter of a fitted effect no physical joint can have, in words."""
    out = []
    for key, value in params.items():
        if key in NON_NEGATIVE and value < 0.0:
            out.append(f"{key} {value:.3g} < 0")
        elif key in POSITIVE and not value > 0.0:
            out.append(f"{key} {value:.3g} <= 0")
        elif not np.isfinite(value):
            out.append(f"{key} is not finite")
    return out


def inertia_from_dynamic(p: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass, first moment m c, inertia about the frame origin) from Pinocchio's ten dynamic
    parameters (m, mcx, mcy, mcz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz)."""
    m, mc = float(p[0]), np.asarray(p[1:4], float)
    ixx, ixy, iyy, ixz, iyz, izz = (float(x) for x in p[4:10])
    inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    return m, mc, inertia


def body_violations(p: np.ndarray, what: str = "link") -> list[str]:
    """Why ten dynamic parameters (Pinocchio's order, inertia about the frame origin) are no
    rigid body, in words (empty: a body can have them)."""
    m, mc, inertia = inertia_from_dynamic(p)
    scale = max(abs(m), float(np.abs(inertia).max()), 1e-12)
    if m < -RELATIVE_TOLERANCE * scale:
        return [f"{what} mass {m:.3g} kg < 0"]
    if m <= RELATIVE_TOLERANCE * scale:
        # no mass: a first moment or an inertia without it is impossible
        return [] if float(np.abs(mc).max()) <= 1e-9 and float(np.abs(inertia).max()) <= 1e-9 else \
            [f"{what} has a first moment or inertia but no mass"]
    c = mc / m
    at_com = inertia - m * (float(c @ c) * np.eye(3) - np.outer(c, c))
    moments = np.linalg.eigvalsh(0.5 * (at_com + at_com.T))
    tolerance = RELATIVE_TOLERANCE * max(float(np.abs(moments).max()), 1e-12)
    out = []
    if moments[0] < -tolerance:
        out.append(f"{what} inertia about its centre of mass not positive (principal moment {moments[0]:.3g} kg m^2)")
    elif moments[2] > moments[0] + moments[1] + tolerance:
        out.append(f"{what} inertia breaks the triangle inequality ({moments[2]:.3g} > {moments[0]:.3g} + "
                   f"{moments[1]:.3g} kg m^2)")
    return out


# Rigid bodies fitted so that they stay bodies: each link's pseudo-inertia J = U U^T with U
# upper triangular and a positive (exponential) diagonal - the log-Cholesky parametrisation
# (Rucker and Wensing, "Smooth parameterization of rigid-body inertia", RA-L 2022). Every
# value of the ten numbers is a physical body and every body with a positive-definite J is
# reached, so a least-squares fit over them is a constrained fit with no bound to clip at.
_UPPER = [(0, 0), (1, 1), (2, 2), (3, 3), (0, 1), (0, 2), (1, 2), (0, 3), (1, 3), (2, 3)]
MIN_PSEUDO_INERTIA = 1e-9       # kg m^2: a massless URDF link is given this much to start from


def pseudo_inertia(p: np.ndarray) -> np.ndarray:
    m, mc, inertia = inertia_from_dynamic(p)
    sigma = 0.5 * np.trace(inertia) * np.eye(3) - inertia
    return np.block([[sigma, mc[:, None]], [mc[None, :], np.array([[m]])]])


def dynamic_from_pseudo(J: np.ndarray) -> np.ndarray:
    sigma, mc, m = J[:3, :3], J[:3, 3], J[3, 3]
    inertia = np.trace(sigma) * np.eye(3) - sigma
    return np.r_[m, mc, inertia[0, 0], inertia[0, 1], inertia[1, 1], inertia[0, 2], inertia[1, 2], inertia[2, 2]]


def to_log_cholesky(p: np.ndarray) -> np.ndarray:
    """Ten numbers whose body (see from_log_cholesky) is the one given (nudged to a strictly
    positive-definite pseudo-inertia where it is only semidefinite)."""
    J = pseudo_inertia(p) + MIN_PSEUDO_INERTIA * np.eye(4)
    flip = np.eye(4)[::-1]
    try:
        lower = np.linalg.cholesky(flip @ J @ flip)
    except np.linalg.LinAlgError:
        lower = np.linalg.cholesky(flip @ (J + (1e-6 - min(np.linalg.eigvalsh(J).min(), 0.0)) * np.eye(4)) @ flip)
    U = flip @ lower @ flip
    return np.array([math.log(U[i, i]) if i == k else U[i, k] for i, k in _UPPER])


def from_log_cholesky(theta: np.ndarray) -> np.ndarray:
    U = np.zeros((4, 4))
    for value, (i, k) in zip(theta, _UPPER):
        U[i, k] = math.exp(value) if i == k else value
    return dynamic_from_pseudo(U @ U.T)


def log_cholesky_jacobian(theta: np.ndarray) -> np.ndarray:
    """d(dynamic parameters) / d theta, (10, 10): J = U U^T is quadratic in U and the map from J
    to the dynamic parameters linear, so each column is that map of dU U^T + U dU^T."""
    U = np.zeros((4, 4))
    for value, (i, k) in zip(theta, _UPPER):
        U[i, k] = math.exp(value) if i == k else value
    out = np.empty((10, 10))
    for col, (i, k) in enumerate(_UPPER):
        dU = np.zeros((4, 4))
        dU[i, k] = U[i, k] if i == k else 1.0
        out[:, col] = dynamic_from_pseudo(dU @ U.T + U @ dU.T)
    return out


def levenberg_marquardt(residual, jacobian, theta: np.ndarray, iterations: int) -> np.ndarray:
    """Minimise |residual(theta)|^2 (a small dense problem). Written out rather than
    scipy's least_squares: its SVD per step on a machine whose cores other processes hold
    ran 10-50x slower than these normal-equation solves (measured)."""
    r = residual(theta)
    cost, damping = float(r @ r), 1e-3
    for _ in range(iterations):
        J = jacobian(theta)
        g, H = J.T @ r, J.T @ J
        scale = np.diag(H) + 1e-12 * max(float(np.max(np.diag(H))), 1e-300)
        while damping < 1e10:
            step = np.linalg.solve(H + damping * np.diag(scale), -g)
            trial = residual(theta + step)
            if float(trial @ trial) < cost:
                break
            damping *= 4.0
        else:
            return theta
        gain = cost - float(trial @ trial)
        theta, r, cost, damping = theta + step, trial, float(trial @ trial), max(damping / 3.0, 1e-9)
        if gain <= 1e-10 * cost:
            break
    return theta
