"""Closed-form IK for 6R chains with a group of parallel axes (up to 8 solutions).

Works on the convention-free chain of model.py, M = Rz(x1) F1 Rz(x2) F2 ... F5 Rz(x6), and
recognises two geometries, on the chain as given or on the reversed chain (T^-1):

* "ppp"  : axes 2, 3, 4 parallel, axes 5 and 6 intersect (UR-like). The ORU test-bed arm
           (reversed: roll - pitch pitch pitch - roll yaw) and the 7-DOF SSRMS arm with
           theta_2 fixed (roll - pitch pitch pitch - yaw roll).
* "ppsw" : axes 2, 3 parallel, axes 4, 5, 6 concurrent (spherical wrist). The laser arm.

Both rest on one fact: the coordinate, along the common direction n of the parallel axes,
of a point c fixed beyond the group (the axis-5/6 intersection or the wrist centre) does
not depend on the group's joint angles. With n = Rz(x1) u this gives
u . Rz(-x1) c = K, a single equation a cos x1 + b sin x1 = k (two roots). The rest follows
from the same kind of equation and a planar two-link problem.

Only exact geometry is handled (nominal parameters). A model with parameter errors is not
recognised; callers fall back to damped least squares (or seed it from the nominal model).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from spacearm.base.kinematics.model import KinematicModel
from spacearm.base.spatial import inv_transform, rotz

Array = NDArray[np.float64]
Z = np.array([0.0, 0.0, 1.0])
GEOMETRY_TOL = 1e-9
TWO_PI = 2.0 * math.pi


def solve_trig(a: float, b: float, k: float, tol: float = 1e-9) -> list[float] | None:
    """Roots of a cos x + b sin x = k; None when a = b = 0 (x free), [] when unreachable."""
    r = math.hypot(a, b)
    if r < 1e-12:
        return None
    ratio = k / r
    if abs(ratio) > 1.0 + tol:
        return []
    ratio = max(-1.0, min(1.0, ratio))
    base = math.atan2(b, a)
    delta = math.acos(ratio)
    return [base + delta, base - delta]


def _rz3(x: float) -> Array:
    c, s = math.cos(x), math.sin(x)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _dot_rz(v: Array, w: Array) -> tuple[float, float, float]:
    """v . Rz(x) w = a cos x + b sin x + c: returns (a, b, c)."""
    return (v[0] * w[0] + v[1] * w[1], v[1] * w[0] - v[0] * w[1], v[2] * w[2])


def _align_angle(r: Array, h: Array) -> float | None:
    """x with Rz(x) r = h (xy parts); None when r is along z (x free)."""
    if math.hypot(r[0], r[1]) < 1e-9:
        return None
    return math.atan2(h[1], h[0]) - math.atan2(r[1], r[0])


def _line_intersection(p1: Array, d1: Array, p2: Array, d2: Array) -> tuple[float, float, float]:
    """Parameters (t1, t2) of the closest points of two lines and their distance."""
    w0 = p1 - p2
    a, b, c = d1 @ d1, d1 @ d2, d2 @ d2
    dd, e = d1 @ w0, d2 @ w0
    den = a * c - b * b
    if den < 1e-18:
        return math.nan, math.nan, math.inf
    t1 = (b * e - c * dd) / den
    t2 = (a * e - b * dd) / den
    return t1, t2, float(np.linalg.norm(p1 + t1 * d1 - p2 - t2 * d2))


def _planar_two_link(p: Array, t2: Array, t3: Array, gamma: float) -> list[tuple[float, float]]:
    """(x2, x3) with Rz(x2) (t2 + Rz(gamma + x3) t3) = p in the xy plane."""
    a, b, c = _dot_rz(np.array([t2[0], t2[1], 0.0]), np.array([t3[0], t3[1], 0.0]))
    k = 0.5 * (p[0] ** 2 + p[1] ** 2 - t2[0] ** 2 - t2[1] ** 2 - t3[0] ** 2 - t3[1] ** 2)
    roots = solve_trig(a, b, k, tol=1e-7)
    out = []
    for delta in roots or []:
        cd, sd = math.cos(delta), math.sin(delta)
        vx = t2[0] + cd * t3[0] - sd * t3[1]
        vy = t2[1] + sd * t3[0] + cd * t3[1]
        x2 = math.atan2(p[1], p[0]) - math.atan2(vy, vx)
        out.append((x2, delta - gamma))
    return out


@dataclass(frozen=True, eq=False)
class Chain6:
    """A 6-joint chain M = F0 Rz(x1) F1 ... Rz(x6) F6 plus its mapping to model joints.

    x_k = sign * (q[joint[k]] + offset[joint[k]]).
    """
    F: Array
    joints: tuple[int, ...]
    sign: float


def _chain_of(model: KinematicModel, fixed: dict[int, float]) -> tuple[Array, list[int]]:
    """Model chain with fixed joints (index -> q value) folded into the fixed transforms."""
    Fs = [np.array(model.F[0])]
    free = []
    for i in range(model.nq):
        if i in fixed and model.joint_types[i] == "prismatic":
            slide = np.eye(4)
            slide[2, 3] = fixed[i]
            Fs[-1] = Fs[-1] @ rotz(model.theta_offset[i]) @ slide @ model.F[i + 1]
        elif i in fixed:
            Fs[-1] = Fs[-1] @ rotz(fixed[i] + model.theta_offset[i]) @ model.F[i + 1]
        else:
            free.append(i)
            Fs.append(np.array(model.F[i + 1]))
    return np.array(Fs), free


def _reverse(F: Array) -> Array:
    return np.array([inv_transform(F[k]) for k in range(len(F) - 1, -1, -1)])


def _axes(F: Array) -> tuple[Array, Array]:
    """Axis directions and points of the chain at x = 0 in the frame of F0's output."""
    T = np.eye(4)
    dirs, pts = [], []
    for k in range(1, len(F)):
        dirs.append(T[:3, 2].copy())
        pts.append(T[:3, 3].copy())
        T = T @ F[k]
    return np.array(dirs), np.array(pts)


def _is_z_rotation(F: Array) -> bool:
    return bool(np.linalg.norm(F[:3, 2] - Z) < GEOMETRY_TOL)


class Solver6:
    """Closed-form solver for one recognised 6R chain (kind 'ppp' or 'ppsw')."""

    def __init__(self, chain: Chain6, kind: str) -> None:
        self.chain, self.kind = chain, kind
        F = chain.F
        self.F0_inv = inv_transform(F[0])
        self.F6_inv = inv_transform(F[6])
        R = [F[k][:3, :3] for k in range(7)]
        self.F = F
        self.u = R[1] @ Z
        self.v = R[4].T @ Z
        self.w = R[5] @ Z
        self.R1, self.R4, self.R5 = R[1], R[4], R[5]
        self.gamma2 = math.atan2(R[2][1, 0], R[2][0, 0])
        self.gamma3 = math.atan2(R[3][1, 0], R[3][0, 0])
        self.t2 = F[2][:2, 3].copy()
        # Point c on axis 6, at parameter s in the frame before Rz(x6): axis 5 there is the
        # line through -R5^T t5 along R5^T z.
        s, _, dist = _line_intersection(np.zeros(3), Z, -R[5].T @ F[5][:3, 3], R[5].T @ Z)
        self.c_local = np.array([0.0, 0.0, s, 1.0])
        if kind == "ppp":
            self.t3 = F[3][:2, 3].copy()
        else:
            # Wrist centre on axis 4 at parameter s4 in the frame before Rz(x4); e is that
            # point seen from the frame after Rz(x3).
            s4, _, _ = _line_intersection(np.zeros(3), Z, F[4][:3, 3], R[4] @ Z)
            self.e = F[3] @ np.array([0.0, 0.0, s4, 1.0])
            self.t3 = self.e[:2].copy()
        c0 = F[1] @ F[2] @ F[3] @ F[4] @ F[5] @ self.c_local
        self.K = float(self.u @ c0[:3])

    @staticmethod
    def detect(chain: Chain6) -> "Solver6 | None":
        """Solver for the chain's geometry, or None when neither pattern matches exactly."""
        F = chain.F
        dirs, pts = _axes(F)
        _, _, d56 = _line_intersection(pts[4], dirs[4], pts[5], dirs[5])
        if _is_z_rotation(F[2]) and _is_z_rotation(F[3]) and d56 < GEOMETRY_TOL \
                and abs(dirs[4] @ dirs[1]) < 1.0 - 1e-6:
            return Solver6(chain, "ppp")
        if _is_z_rotation(F[2]):
            t45, _, d45 = _line_intersection(pts[3], dirs[3], pts[4], dirs[4])
            t56, _, _ = _line_intersection(pts[5], dirs[5], pts[4], dirs[4])
            if d45 < GEOMETRY_TOL and d56 < GEOMETRY_TOL and np.linalg.norm(
                    pts[3] + t45 * dirs[3] - pts[5] - t56 * dirs[5]) < GEOMETRY_TOL:
                return Solver6(chain, "ppsw")
        return None

    def solve(self, M_target: Array, hint: Array | None = None) -> list[Array]:
        """All chain-angle solutions x (6,) for chain pose M_target (F0 ... F6 included)."""
        hint = np.zeros(6) if hint is None else hint
        M = self.F0_inv @ M_target @ self.F6_inv
        c = (M @ self.c_local)[:3]
        u = self.u
        a, b, k0 = _dot_rz(u, np.array([c[0], c[1], c[2]]))
        # u . Rz(-x) c = a cos x - b sin x + k0
        roots = solve_trig(a, -b, self.K - k0)
        x1s = [hint[0]] if roots is None else roots
        sols = []
        for x1 in x1s:
            H = rotz(x1) @ self.F[1]
            sols.extend(self._ppp(M, H, x1, hint) if self.kind == "ppp"
                        else self._ppsw(M, H, x1, c, hint))
        return sols

    def _wrist_pair(self, R_rel_z: float, n_in_M: Array, hint: Array) -> list[tuple[float, float]]:
        """(x5, x6) from v . Rz(x5) w = R_rel_z and Rz(x6) n_in_M = R5^T Rz(-x5) v."""
        a, b, c = _dot_rz(self.v, self.w)
        roots = solve_trig(a, b, R_rel_z - c)
        out = []
        for x5 in ([hint[4]] if roots is None else roots):
            h = self.R5.T @ (_rz3(-x5) @ self.v)
            x6 = _align_angle(n_in_M, h)
            out.append((x5, hint[5] if x6 is None else x6))
        return out

    def _ppp(self, M: Array, H: Array, x1: float, hint: Array) -> list[Array]:
        n = H[:3, 2]
        R_M = M[:3, :3]
        out = []
        for x5, x6 in self._wrist_pair(float(n @ R_M[:, 2]), R_M.T @ n, hint):
            tail = self.F[4] @ rotz(x5) @ self.F[5] @ rotz(x6)
            G = M @ inv_transform(tail)          # frame before Rz(x4), rotated by x4
            Rphi = H[:3, :3].T @ G[:3, :3]
            phi = math.atan2(Rphi[1, 0], Rphi[0, 0])
            p = inv_transform(H) @ G[:, 3]
            for x2, x3 in _planar_two_link(p, self.t2, self.t3, self.gamma2):
                x4 = phi - x2 - x3 - self.gamma2 - self.gamma3
                out.append(np.array([x1, x2, x3, x4, x5, x6]))
        return out

    def _ppsw(self, M: Array, H: Array, x1: float, c: Array, hint: Array) -> list[Array]:
        p = inv_transform(H) @ np.append(c, 1.0)
        out = []
        for x2, x3 in _planar_two_link(p, self.t2, self.t3, self.gamma2):
            B4 = H @ rotz(x2) @ self.F[2] @ rotz(x3) @ self.F[3]
            R = B4[:3, :3].T @ M[:3, :3]
            for x5, x6 in self._wrist_pair(float(R[2, 2]), R[2, :].copy(), hint):
                Rx4 = R @ (self.R4 @ _rz3(x5) @ self.R5 @ _rz3(x6)).T
                x4 = math.atan2(Rx4[1, 0], Rx4[0, 0])
                out.append(np.array([x1, x2, x3, x4, x5, x6]))
        return out


@dataclass(frozen=True, eq=False)
class AnalyticIK:
    """Analytic IK bound to a model (and optionally a fixed joint)."""
    model: KinematicModel
    solver: Solver6
    fixed: tuple[tuple[int, float], ...]

    def chain_angles_to_q(self, x: Array) -> Array:
        m = self.model
        q = np.empty(m.nq)
        for i, value in self.fixed:
            q[i] = value
        for k, j in enumerate(self.solver.chain.joints):
            q[j] = self.solver.chain.sign * x[k] - m.theta_offset[j]
        return q

    def q_to_chain_angles(self, q: Array) -> Array:
        m, ch = self.model, self.solver.chain
        return np.array([ch.sign * (q[j] + m.theta_offset[j]) for j in ch.joints])

    def solve(self, T: ArrayLike, q_hint: ArrayLike | None = None, tol: float = 1e-7) -> list[Array]:
        """Distinct solutions with angles wrapped to [-pi, pi), checked against FK to `tol`."""
        from spacearm.base.kinematics.forward import fk_batch
        from spacearm.base.kinematics.pose_error import pose_errors_batch, wrap_angle

        T = np.asarray(T, dtype=float)
        hint = None if q_hint is None else self.q_to_chain_angles(np.asarray(q_hint, float))
        M = T if self.solver.chain.sign > 0 else inv_transform(T)
        xs = self.solver.solve(M, hint)
        if not xs:
            return []
        Q = wrap_angle(np.array([self.chain_angles_to_q(x) for x in xs]))
        for i, value in self.fixed:
            Q[:, i] = value
        pos, ang = pose_errors_batch(np.broadcast_to(T, (len(Q), 4, 4)), fk_batch(self.model, Q))
        Q = Q[(pos <= tol * max(1.0, self.model.reach)) & (ang <= tol)]
        unique: list[Array] = []
        for q in Q:
            if all(np.max(np.abs(wrap_angle(q - u))) > 1e-6 for u in unique):
                unique.append(q)
        return unique


@functools.lru_cache(maxsize=64)
def _analytic_for(model: KinematicModel, fixed: tuple[tuple[int, float], ...]) -> AnalyticIK | None:
    fixed_map = dict(fixed)
    if any(t == "prismatic" for i, t in enumerate(model.joint_types) if i not in fixed_map):
        return None   # the closed forms are for six revolute joints
    F, free = _chain_of(model, fixed_map)
    if len(free) != 6:
        return None
    for sign, Fc, joints in ((1.0, F, tuple(free)), (-1.0, _reverse(F), tuple(reversed(free)))):
        solver = Solver6.detect(Chain6(Fc, joints, sign))
        if solver is not None:
            return AnalyticIK(model, solver, fixed)
    return None


def analytic_solver(model: KinematicModel, fixed: dict[int, float] | None = None
                    ) -> AnalyticIK | None:
    """Closed-form solver for the model (joints in `fixed` held at given q), or None."""
    key = tuple(sorted((int(i), float(v)) for i, v in (fixed or {}).items()))
    # Held-joint values change from call to call; caching them would only evict the rest.
    return _analytic_for.__wrapped__(model, key) if key else _analytic_for(model, key)


def expand_wraps(model: KinematicModel, q: ArrayLike) -> list[Array]:
    """All copies of q shifted by multiples of 2 pi per joint that lie within the limits."""
    q = np.asarray(q, dtype=float)
    choices = []
    for i in range(model.nq):
        if model.joint_types[i] == "prismatic":
            choices.append([q[i]])
            continue
        lo = math.ceil((model.q_min[i] - q[i]) / TWO_PI - 1e-12)
        hi = math.floor((model.q_max[i] - q[i]) / TWO_PI + 1e-12)
        choices.append([q[i] + k * TWO_PI for k in range(lo, hi + 1)])
    grids = np.meshgrid(*choices, indexing="ij")
    return [row for row in np.stack([g.ravel() for g in grids], axis=1)]


def analytic_ik(model: KinematicModel, T: ArrayLike, q_hint: ArrayLike | None = None,
                fixed: dict[int, float] | None = None, within_limits: bool = True) -> list[Array]:
    """All closed-form solutions for pose T.

    within_limits=False: one representative per branch, angles in [-pi, pi).
    within_limits=True: every 2 pi copy inside the joint limits (several per branch when a
    joint range exceeds one turn). Raises ValueError when the geometry is not recognised.
    """
    solver = analytic_solver(model, fixed)
    if solver is None:
        raise ValueError(f"no closed-form IK for {model.name!r} with fixed joints {fixed or {}}")
    sols = solver.solve(T, q_hint)
    if not within_limits:
        return sols
    out: list[Array] = []
    for q in sols:
        out.extend(expand_wraps(model, q))
    return out
