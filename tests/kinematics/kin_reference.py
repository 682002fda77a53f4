"""Reference FK written straight from the papers' formulas, one explicit matrix per step.

Deliberately naive and independent of spacearm.base.kinematics (no shared chain reduction), so
that the tests compare two derivations rather than one code path with itself.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np


def Rx(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def Ry(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def Rz(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def Tx(x):
    T = np.eye(4)
    T[0, 3] = x
    return T


def Tz(z):
    T = np.eye(4)
    T[2, 3] = z
    return T


def laser_paper_A(theta, alpha, a, d, beta):
    """Laser paper eq. (2): the standard D-H matrix (1) post-multiplied by Rot(y, beta)."""
    Ct, St, Ca, Sa, Cb, Sb = (math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha),
                              math.cos(beta), math.sin(beta))
    return np.array([
        [Ct * Cb - St * Sa * Sb, -St * Ca, Ct * Sb + St * Sa * Cb, a * Ct],
        [St * Cb + Ct * Sa * Sb, Ct * Ca, St * Sb - Ct * Sa * Cb, a * St],
        [-Ca * Sb, Sa, Ca * Cb, d],
        [0, 0, 0, 1.0]])


def ekf_paper_T(a_prev, alpha_prev, d, theta):
    """EKF paper eq. (1): the modified (Craig) D-H matrix, element by element."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha_prev), math.sin(alpha_prev)
    return np.array([
        [ct, -st, 0, a_prev],
        [st * ca, ct * ca, -sa, -sa * d],
        [st * sa, ct * sa, ca, ca * d],
        [0, 0, 0, 1.0]])


def reference_fk(model, q):
    """base * prod(link_i(q_i)) * tool from elementary products (beta included)."""
    T = np.array(model.base)
    for i in range(model.nq):
        th = q[i] + model.theta_offset[i]
        a, al, d, be = model.a[i], model.alpha[i], model.d[i], model.beta[i]
        if model.convention == "standard":
            T = T @ Rz(th) @ Tz(d) @ Tx(a) @ Rx(al) @ Ry(be)
        else:
            T = T @ Rx(al) @ Tx(a) @ Ry(be) @ Rz(th) @ Tz(d)
    return T @ model.tool


def numeric_jacobian(fk_fn, q, h=1e-6):
    """Central differences: linear rows from the origin, angular from log(R+ R-^T)/2h."""
    n = len(q)
    J = np.zeros((6, n))
    for i in range(n):
        dq = np.zeros(n)
        dq[i] = h
        Tp, Tm = fk_fn(q + dq), fk_fn(q - dq)
        J[:3, i] = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
        dR = Tp[:3, :3] @ Tm[:3, :3].T
        J[3:, i] = np.array([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0], dR[1, 0] - dR[0, 1]]) / (4 * h)
    return J


ARM_DIR = Path(__file__).resolve().parents[2] / "configs" / "arm"
ARMS = ("oru_testbed_6dof", "space_robot_6dof_laser", "ssrms_7dof")
