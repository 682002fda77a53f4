"""Numerical IK (damped least squares) and the combined solver with analytic fallbacks."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from spacearm.base.kinematics.analytic_ik import analytic_solver, expand_wraps
from spacearm.base.kinematics.forward import compute_chain
from spacearm.base.kinematics.jacobian import jacobian_from_chain
from spacearm.base.kinematics.model import KinematicData, KinematicModel
from spacearm.base.spatial import matrix_to_rotvec

Array = NDArray[np.float64]

# Final accuracy asked of every solve; well inside the 1e-6 m / 1e-6 rad contract and
# still far above FK round-off (~1e-15 relative).
TOL_POS = 1e-9
TOL_ROT = 1e-9
# Offsets (rad) of the held joint tried by the 7-DOF fallback, nearest first. The window of
# arm-plane angles that reach a pose can be only a few hundredths of a radian wide.
FIXED_JOINT_STEPS = tuple(sorted(np.arange(-1.5, 1.5001, 0.025), key=abs))
FIRST_ATTEMPT_ITER = 25
# Distance (rad) the retry pulls a seed inside the joint limits.
LIMIT_MARGIN = 0.2
# Arms without a closed form: DLS restarts from seeds up to RESTARTS * RESTART_SPREAD rad away.
RESTARTS = 8
RESTART_SPREAD = 0.25
RESTART_SEED = 20261124


@dataclass
class IKResult:
    """Outcome of an IK solve (scipy.optimize style)."""
    q: Array
    success: bool
    iterations: int
    pos_error: float   # m
    rot_error: float   # rad
    message: str

    def __bool__(self) -> bool:
        return self.success


def _error(data: KinematicData, T_target: Array, e: Array) -> tuple[float, float]:
    """Fill e (6,) with the twist error of the current end pose; return (|dp|, angle)."""
    Tc = data.B[-1]
    np.subtract(T_target[:3, 3], Tc[:3, 3], out=e[:3])
    e[3:] = matrix_to_rotvec(T_target[:3, :3] @ Tc[:3, :3].T)
    return math.sqrt(e[0] ** 2 + e[1] ** 2 + e[2] ** 2), math.sqrt(e[3] ** 2 + e[4] ** 2 + e[5] ** 2)


def solve_dls(model: KinematicModel, data: KinematicData, T_target: ArrayLike, q0: ArrayLike, *,
              max_iter: int = 60, tol_pos: float = TOL_POS, tol_rot: float = TOL_ROT,
              respect_limits: bool = True, locked: tuple[int, ...] = ()) -> IKResult:
    """Damped least squares (Levenberg-Marquardt) from q0.

    Error e = (dp; rotvec(R_t R^T)) with the position rows scaled by 1/reach so that metres and
    radians weigh alike. Damping lambda = mu * |e|^2 (Sugihara): large far away, vanishing at
    the solution for quadratic convergence; mu grows tenfold on a rejected step. Joint limits:
    the step is clipped to the box, and joints pinned at a bound are dropped from the next
    step so the others can still make progress. Joints listed in `locked` stay at q0.
    """
    T_target = np.asarray(T_target, dtype=float)
    n = model.nq
    lo, hi = model.q_min, model.q_max
    q = np.array(q0, dtype=float)
    if respect_limits:
        np.clip(q, lo, hi, out=q)
    w = 1.0 / max(model.reach, 1e-3)
    W = np.array([w, w, w, 1.0, 1.0, 1.0])
    Wcol = W[:, None]
    e = np.empty(6)
    compute_chain(model, data, q)
    pos, rot = _error(data, T_target, e)
    ew = W * e
    E = float(ew @ ew)
    J = jacobian_from_chain(data) * Wcol
    mu = 1.0
    movable = np.ones(n, dtype=bool)
    movable[list(locked)] = False
    free = movable.copy()
    all_free = bool(free.all())
    wide = n >= 6
    it = 0
    while it < max_iter:
        if pos <= tol_pos and rot <= tol_rot:
            return IKResult(q, True, it, pos, rot, "converged")
        it += 1
        Jm = J
        if not all_free:
            Jm = J.copy()
            Jm[:, ~free] = 0.0
        lam = mu * E + 1e-12
        if wide:
            # dq = J^T (J J^T + lam I)^-1 e: the min-norm step for redundant arms too.
            H = Jm @ Jm.T
            H.flat[::7] += lam
            dq = Jm.T @ np.linalg.solve(H, ew)
        else:
            H = Jm.T @ Jm
            H.flat[::n + 1] += lam
            dq = np.linalg.solve(H, Jm.T @ ew)
        q_new = q + dq
        if respect_limits:
            np.maximum(q_new, lo, out=q_new)
            np.minimum(q_new, hi, out=q_new)
        compute_chain(model, data, q_new)
        e_new = np.empty(6)
        pos_new, rot_new = _error(data, T_target, e_new)
        ew_new = W * e_new
        E_new = float(ew_new @ ew_new)
        if E_new < E:
            q, e, ew, E, pos, rot = q_new, e_new, ew_new, E_new, pos_new, rot_new
            J = jacobian_from_chain(data) * Wcol
            mu = max(mu * 0.3, 1e-3)
            if respect_limits:
                pinned = ((q <= lo) & (dq < 0.0)) | ((q >= hi) & (dq > 0.0))
                np.logical_and(movable, ~pinned, out=free)
                all_free = bool(free.all())
        else:
            # Rejected: J still belongs to q (data.B now holds q_new; it is scratch).
            if not np.array_equal(free, movable):
                free[:] = movable  # maybe the pinned joint has to come off its bound
                all_free = bool(free.all())
            mu *= 10.0
            if mu > 1e8:
                return IKResult(q, False, it, pos, rot, "stalled (local minimum or limit)")
    ok = pos <= tol_pos and rot <= tol_rot
    return IKResult(q, ok, it, pos, rot, "converged" if ok else "iteration limit reached")


def _closest(candidates: list[Array], q0: Array) -> list[Array]:
    return sorted(candidates, key=lambda q: float(np.linalg.norm(q - q0)))


def solve_ik(model: KinematicModel, data: KinematicData, T_target: ArrayLike, q0: ArrayLike, *,
             max_iter: int = 60, tol_pos: float = TOL_POS, tol_rot: float = TOL_ROT,
             analytic_model: KinematicModel | None = None) -> IKResult:
    """IK from seed q0: DLS first; if it fails, analytic solutions nearest q0 polished by DLS.

    analytic_model: nominal model whose closed form seeds the fallback when `model` itself has
    no exact closed form (e.g. a calibrated model with parameter errors). For a 7-DOF arm the
    fallback holds joint 2 (index 1) at q0's value (EKF paper, Section 2.2).
    """
    q0 = np.asarray(q0, dtype=float)
    # From a nearby seed DLS converges in ~5 iterations; a first attempt that is still far
    # off after FIRST_ATTEMPT_ITER is cheaper to restart from the closed form than to finish.
    res = solve_dls(model, data, T_target, q0, max_iter=min(max_iter, FIRST_ATTEMPT_ITER),
                    tol_pos=tol_pos, tol_rot=tol_rot)
    if res.success:
        return res
    # A seed on or past a bound can pin a joint there; retry from a seed pulled inside.
    margin = np.minimum(LIMIT_MARGIN, 0.25 * (model.q_max - model.q_min))
    inner = np.clip(q0, model.q_min + margin, model.q_max - margin)
    if not np.array_equal(inner, q0):
        retry = solve_dls(model, data, T_target, inner, max_iter=max_iter, tol_pos=tol_pos,
                          tol_rot=tol_rot)
        retry.iterations += res.iterations
        if retry.success:
            retry.message = "converged from seed moved inside the limits"
            return retry
        res = retry
    ref = analytic_model if analytic_model is not None else model
    candidates: list[Array] = []
    if ref.nq == 7:
        # Try the seed's arm plane first, then nearby planes: the seed's own theta_2 may
        # admit no solution for this pose.
        for step in FIXED_JOINT_STEPS:
            solver = analytic_solver(ref, {1: float(q0[1]) + step})
            if solver is None:
                return _perturbed_restarts(model, data, T_target, q0, res, max_iter, tol_pos, tol_rot)
            for q in solver.solve(T_target, q0):
                candidates.extend(expand_wraps(model, q))
            if candidates:
                break
    else:
        solver = analytic_solver(ref)
        if solver is None:
            return _perturbed_restarts(model, data, T_target, q0, res, max_iter, tol_pos, tol_rot)
        for q in solver.solve(T_target, q0):
            candidates.extend(expand_wraps(model, q))
    res = _first_from_seeds(model, data, T_target, _closest(candidates, q0)[:8], res, max_iter, tol_pos,
                            tol_rot, "converged from analytic seed")
    if not res.success:
        res.message += "; analytic seeds failed" if candidates else "; no analytic solution (unreachable?)"
    return res


def _first_from_seeds(model: KinematicModel, data: KinematicData, T_target: Array, seeds, res: IKResult,
                      max_iter: int, tol_pos: float, tol_rot: float, message: str) -> IKResult:
    """DLS from each seed in turn: the first success (iterations summed), else `res`."""
    total = res.iterations
    for q in seeds:
        r = solve_dls(model, data, T_target, q, max_iter=max_iter, tol_pos=tol_pos, tol_rot=tol_rot)
        total += r.iterations
        if r.success:
            r.iterations = total
            r.message = message
            return r
    res.iterations = total
    return res


def _perturbed_restarts(model: KinematicModel, data: KinematicData, T_target: Array, q0: Array,
                        res: IKResult, max_iter: int, tol_pos: float, tol_rot: float) -> IKResult:
    """Arms without a closed form (imported 7-joint arms, prismatic joints): DLS from seeds
    scattered ever wider around q0 inside the limits (fixed generator: reproducible)."""
    rng = np.random.default_rng(RESTART_SEED)
    margin = np.minimum(LIMIT_MARGIN, 0.25 * (model.q_max - model.q_min))
    seeds = (np.clip(q0 + rng.uniform(-RESTART_SPREAD * (k + 1), RESTART_SPREAD * (k + 1), model.nq),
                     model.q_min + margin, model.q_max - margin) for k in range(RESTARTS))
    res = _first_from_seeds(model, data, T_target, seeds, res, max_iter, tol_pos, tol_rot,
                            "converged from a perturbed seed")
    if not res.success:
        res.message += f"; no closed form, {RESTARTS} perturbed seeds failed"
    return res


def ik_fixed_joint(model: KinematicModel, T_target: ArrayLike, fixed_value: float, q0: ArrayLike,
                   fixed_index: int = 1, data: KinematicData | None = None,
                   nominal: KinematicModel | None = None) -> IKResult:
    """7-DOF IK with one joint held (EKF paper, Section 2.2: theta_2 fixes the arm plane).

    Among all closed-form solutions, including every 2 pi copy within the joint limits, returns
    the one with the least joint motion from q0 (Euclidean norm of q - q0). When `model` has
    parameter errors (no exact closed form), the closed form of `nominal` seeds DLS with the
    held joint locked, and the least-motion converged solution is returned.
    """
    q0 = np.asarray(q0, dtype=float)
    T_target = np.asarray(T_target, dtype=float)
    data = KinematicData(model) if data is None else data
    fixed = {fixed_index: float(fixed_value)}
    exact = analytic_solver(model, fixed)
    solver = exact if exact is not None else (
        analytic_solver(nominal, fixed) if nominal is not None else None)
    if solver is None:
        raise ValueError(f"no closed-form IK for {model.name!r} with joint {fixed_index} fixed"
                         + ("" if nominal is not None else "; pass the nominal model"))
    candidates: list[Array] = []
    for q in solver.solve(T_target, q0):
        candidates.extend(expand_wraps(model, q))
    e = np.empty(6)
    if exact is not None:
        for best in _closest(candidates, q0):
            compute_chain(model, data, best)
            pos, rot = _error(data, T_target, e)
            if pos <= 10 * TOL_POS and rot <= 10 * TOL_ROT:
                return IKResult(best, True, 0, pos, rot,
                                f"least motion of {len(candidates)} closed-form solutions")
    else:
        polished = []
        for seed in candidates:
            r = solve_dls(model, data, T_target, seed, locked=(fixed_index,))
            if r.success:
                polished.append(r)
        if polished:
            best = min(polished, key=lambda r: float(np.linalg.norm(r.q - q0)))
            best.message = f"least motion of {len(polished)} polished solutions"
            return best
    compute_chain(model, data, q0)
    pos, rot = _error(data, T_target, e)
    return IKResult(q0.copy(), False, 0, pos, rot, "no solution within limits")
