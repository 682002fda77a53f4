"""Start values of the measurement set-up estimated from the data before the fit.

A user knows where a draw-wire anchor or a marker is only roughly; the fit should not depend on
that guess, nor reject a fit for moving away from it. Before identifiability and the fit:

  range  anchor and wire length offset by multilateration (a sphere fit): with p_k the measured
         point at the nominal arm, L_k = |p_k - a| + l0 is linear in (a, l0, |a|^2 - l0^2) after
         squaring, then a few Gauss-Newton steps on the distances themselves;
  point  registration of the measurement frame (Kabsch) alternated with the marker's point on
         the tool (linear given the rotation), see `register_points`; without a registration
         only the marker point (linear).
The given start is used only where the data cannot give one (a non-finite solution), so the
start of the fit, and the kept parameter set, do not depend on the user's guess.
"""
from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from spacearm.controller.calibration.composite import Block
from spacearm.controller.calibration.errormodel import ErrorModel
from spacearm.controller.calibration.measurement_models import PointModel, PoseModel, RangeModel

Array = NDArray[np.float64]


def kabsch(P: Array, Q: Array) -> Array:
    """Rigid transform T with Q ~= T P (rows are points)."""
    cp, cq = P.mean(0), Q.mean(0)
    U, _, Vt = np.linalg.svd((P - cp).T @ (Q - cq))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    T = np.eye(4)
    T[:3, :3] = Vt.T @ D @ U.T
    T[:3, 3] = cq - T[:3, :3] @ cp
    return T


def sphere_fit(origins: Array, R: Array, lengths: Array, t0: Array,
               free_t: bool = True) -> tuple[Array, float, Array] | None:
    """Anchor a, length offset l0 and tool point t with lengths ~= |o + R t - a| + l0, or None.

    Linear multilateration at t0 for the start, then Gauss-Newton on all seven unknowns (t held
    at t0 unless `free_t`)."""
    t = np.asarray(t0, float)
    p = origins + np.einsum("nij,j->ni", R, t)
    M = np.column_stack([-2.0 * p, 2.0 * lengths, np.ones(len(p))])
    sol, *_ = np.linalg.lstsq(M, lengths ** 2 - np.sum(p ** 2, axis=1), rcond=None)
    a, off = sol[:3], float(sol[3])
    for _ in range(30):
        v = origins + np.einsum("nij,j->ni", R, t) - a
        d = np.maximum(np.linalg.norm(v, axis=1), 1e-12)
        u = v / d[:, None]
        r = lengths - d - off
        # d(prediction)/d(a, l0, t) = (-u, 1, u^T R)
        J = np.column_stack([-u, np.ones(len(p)), np.einsum("ni,nij->nj", u, R)])
        step, *_ = np.linalg.lstsq(J if free_t else J[:, :4], r, rcond=None)
        if not np.all(np.isfinite(step)):
            return None
        step = np.concatenate([step, np.zeros(7 - len(step))])
        a, off, t = a + step[:3], off + float(step[3]), t + step[4:]
        if np.linalg.norm(step) < 1e-10:
            break
    return (a, off, t) if np.all(np.isfinite(a)) and np.isfinite(off) else None


def register_points(P: Array, R: Array, M: Array, t0: Array, iterations: int = 10) -> tuple[Array, Array]:
    """Measurement frame <- base (4x4) and tool point t with M_k ~= W (P_k + R_k t) (Kabsch/linear)."""
    t = np.asarray(t0, float)
    W = kabsch(P + np.einsum("nij,j->ni", R, t), M)
    for _ in range(iterations):
        # Given W's rotation: M_k - Rw P_k = Rw R_k t + tw, linear in (t, tw).
        Rw = W[:3, :3]
        A = np.concatenate([np.einsum("ij,njk->nik", Rw, R), np.broadcast_to(np.eye(3), (len(P), 3, 3))], axis=2)
        b = M - P @ Rw.T
        sol, *_ = np.linalg.lstsq(A.reshape(-1, 6), b.reshape(-1), rcond=None)
        t = sol[:3]
        W = kabsch(P + np.einsum("nij,j->ni", R, t), M)
    return W, t


def estimate_starts(em: ErrorModel, blocks: list[Block], candidates: list[str] | None = None) -> list[Block]:
    """Blocks whose range and point instruments start from the data's own estimate (module doc).
    Only parameters among `candidates` (default: all) move; a parameter the user holds fixed stays."""
    x = em.nominal

    def free(names: tuple[str, ...]) -> bool:
        return candidates is None or all(n in candidates for n in names)
    new: dict[int, object] = {}
    for b in blocks:
        m = b.model
        if id(m) in new or isinstance(m, PoseModel):
            continue
        T = em.poses(x, b.Q)
        if isinstance(m, RangeModel):
            if not free(m.extra_names[:4]):
                continue
            fit = sphere_fit(T[:, :3, 3], T[:, :3, :3], np.reshape(b.measured, -1), np.asarray(m.tool_point, float),
                             free(m.extra_names[4:]))
            if fit is not None:
                a, off, t = fit
                new[id(m)] = dataclasses.replace(m, anchor=tuple(map(float, a)), length_offset=off,
                                                 tool_point=tuple(map(float, t)))
        elif isinstance(m, PointModel) and free(m.extra_names):
            R = T[:, :3, :3]
            # M_k - p_k = R_k t: linear in the tool point when the data are in the arm's frame.
            t, *_ = np.linalg.lstsq(R.reshape(-1, 3), (b.measured - T[:, :3, 3]).reshape(-1), rcond=None)
            if np.all(np.isfinite(t)):
                new[id(m)] = dataclasses.replace(m, tool_point=tuple(map(float, t)))
    return [dataclasses.replace(b, model=new.get(id(b.model), b.model)) if id(b.model) in new else b
            for b in blocks]
