"""Identifiable parameter set from the identification Jacobian (SVD for the rank, ordered QR for which).

Procedure (deterministic):
 1. Evaluate the Jacobian on a well-spread random configuration set (fixed seed).
 2. Scale every column to unit norm, so metres and radians compete fairly.
 3. SVD of the scaled Jacobian -> numerical rank r (singular values below tol * s_max are zero).
 4. Ordered Gram-Schmidt (QR with a priority order instead of norm pivoting): walk the
    candidates in priority order and keep a column if its part orthogonal to the kept ones is
    larger than `tol`; otherwise it is dropped and explained by regressing it on the kept columns.
    The priority order makes ties (exactly dependent columns) resolve the textbook way:
    theta, d, a, alpha first; Hayati beta after them; the d of a link whose two axes are parallel
    (the d that beta replaces) last; frames and the plane's gauge after the arm.
 5. Check that the kept set has rank r.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spacearm.controller.calibration.residuals import Problem

Array = NDArray[np.float64]


@dataclass
class Dropped:
    name: str
    reason: str


@dataclass
class IdentifiabilityReport:
    kept: list[str]
    dropped: list[Dropped]
    rank: int
    singular_values: Array
    condition: float          # of the scaled kept columns

    def summary(self) -> str:
        lines = [f"identifiable: {len(self.kept)} parameters (rank {self.rank}), "
                 f"condition {self.condition:.3g}", "  kept: " + ", ".join(self.kept)]
        lines += [f"  dropped {d.name}: {d.reason}" for d in self.dropped]
        return "\n".join(lines)


def parallel_links(problem: Problem, tol: float = 1e-3) -> list[int]:
    """Joint indices i (0-based) whose link twist is ~0 or ~pi: axes i and i+1 parallel."""
    kin = problem.model.kin
    return [i for i in range(kin.nq) if abs(np.sin(kin.alpha[i])) < tol]


def priority_order(problem: Problem, candidates: list[str], gauge: str | None = None) -> list[str]:
    """Candidates sorted by keep-preference (see module docstring)."""
    kin = problem.model.kin
    hayati_d = set()
    for i in parallel_links(problem):
        # standard D-H: alpha_i ~ 0 means z_{i-1} || z_i, so d_i slides along the same line as
        # d_{i+1}; Hayati replaces d_i by beta_i. Modified rows carry alpha_{i-1}: d_{i-1}... here
        # alpha on joint i+1 row couples d_i and d_{i+1}; the earlier d is the one replaced.
        if kin.convention == "standard":
            hayati_d.add(f"d_{i + 1}")
        elif i >= 1:
            hayati_d.add(f"d_{i}")
    plane_last = {f"{problem.plane.prefix}_f"} if problem.plane is not None else set()
    gauge_set = {gauge} if gauge else set()

    def tier(name: str) -> float:
        kind = name.rsplit("_", 1)[0]
        if name in gauge_set or name in plane_last:
            return 6
        if name in hayati_d:
            return 5
        if kind in ("theta", "d", "a", "alpha"):
            return 0
        if kind == "beta":
            return 1
        if problem.plane is not None and name.startswith(problem.plane.prefix + "_"):
            return 4
        if name.endswith(("_tx", "_ty", "_tz", "_ax", "_ay", "_az")):
            # An instrument's placement first (a marker on the tool, a draw-wire anchor): it is
            # what is really uncertain, and the first/last joints' D-H rows (which the data cannot
            # tell from it) would otherwise absorb a roughly known anchor or marker as degrees
            # and decimetres of arm "error".
            return -1
        if name.startswith(problem.model.tool_prefix + "_"):
            return 2.5
        if name.startswith(problem.model.world_prefix + "_"):
            return 3
        return 4  # an instrument's own parameters (anchor, tool point)

    pos = {n: i for i, n in enumerate(problem.names)}
    return sorted(candidates, key=lambda n: (tier(n), pos[n]))


def identifiability_jacobian(problem: Problem, candidates: list[str], n_configs: int = 200,
                             seed: int = 0, Q: Array | None = None) -> Array:
    """Stacked Jacobian (rows, len(candidates)) at the nominal parameters on random postures."""
    kin = problem.model.kin
    if Q is None:
        Q = kin.random_configurations(n_configs, np.random.default_rng(seed), margin=0.05)
    x = problem.nominal()
    meas = problem.predict(x, Q)
    _, A = problem.residual_and_jacobian(x, Q, meas)
    if problem.kind == "plane":
        # Postures whose beam misses the plane (or runs away from it) carry no information.
        h = meas
        nb = problem.model.poses(x[: problem.model.n_params], Q)[:, :3, 2] @ problem.plane.values[:3]
        ok = (h > 0) & (np.abs(nb) > 0.2 * np.linalg.norm(problem.plane.values[:3]))
        A = A[ok]
    idx = np.array([problem.names.index(n) for n in candidates])
    return A.reshape(-1, A.shape[-1])[:, idx]


def find_identifiable(problem: Problem, candidates: list[str] | None = None, n_configs: int = 200,
                      seed: int = 0, tol: float = 1e-6, gauge: str | None = None,
                      Q: Array | None = None, A: Array | None = None) -> IdentifiabilityReport:
    """The identifiable subset of `candidates` (default: all parameters) with reasons for drops.

    `A` (rows, len(candidates)) is a given identification Jacobian, e.g. on the data's own
    postures (see fit_checks.data_identifiability); otherwise it is evaluated on Q or random postures.
    """
    candidates = list(problem.names) if candidates is None else list(candidates)
    if A is None:
        A = identifiability_jacobian(problem, candidates, n_configs, seed, Q)
    norms = np.linalg.norm(A, axis=0)
    dropped: list[Dropped] = []
    usable = []
    for j, name in enumerate(candidates):
        if norms[j] < 1e-12 * max(norms.max(), 1e-300):
            dropped.append(Dropped(name, "no effect on the measurement"))
        else:
            usable.append(j)
    As = A[:, usable] / norms[usable]
    s = np.linalg.svd(As, compute_uv=False)
    rank = int(np.sum(s > tol * s[0] * max(As.shape) ** 0.5)) if s.size else 0
    order = priority_order(problem, [candidates[j] for j in usable], gauge)
    col = {candidates[j]: As[:, k] for k, j in enumerate(usable)}
    basis: list[Array] = []
    kept: list[str] = []
    for name in order:
        v = col[name].copy()
        for b in basis:          # twice for numerical orthogonality (classical trick)
            v -= (b @ v) * b
        for b in basis:
            v -= (b @ v) * b
        nv = np.linalg.norm(v)
        if nv > np.sqrt(tol) and len(kept) < rank:
            basis.append(v / nv)
            kept.append(name)
        else:
            dropped.append(Dropped(name, _explain(name, col, kept, problem)))
    kept_sorted = [n for n in candidates if n in kept]
    K = np.column_stack([col[n] for n in kept_sorted]) if kept else np.zeros((A.shape[0], 0))
    sk = np.linalg.svd(K, compute_uv=False) if kept else np.array([1.0])
    if np.linalg.matrix_rank(K, tol=tol * sk[0] * max(K.shape) ** 0.5) != len(kept):
        raise RuntimeError("kept columns are not independent; lower tol")
    pos = {n: i for i, n in enumerate(candidates)}
    dropped.sort(key=lambda d: pos[d.name])
    return IdentifiabilityReport(kept_sorted, dropped, rank, s, float(sk[0] / sk[-1]))


def _explain(name: str, col: dict[str, Array], kept: list[str], problem: Problem) -> str:
    """Which kept parameters reproduce this column (largest regression weights)."""
    if not kept:
        return "no independent effect"
    K = np.column_stack([col[n] for n in kept])
    w, *_ = np.linalg.lstsq(K, col[name], rcond=None)
    fit = np.linalg.norm(K @ w - col[name])
    big = [kept[i] for i in np.argsort(-np.abs(w)) if abs(w[i]) > 0.05 * np.abs(w).max()][:3]
    reason = f"dependent on {', '.join(big)}"
    if fit > 1e-3:
        reason = f"nearly dependent on {', '.join(big)} (residual {fit:.1e})"
    kin = problem.model.kin
    kind, _, idx = name.rpartition("_")
    if kind == "d" and idx.isdigit():
        i = int(idx) - 1
        pair = (i + 1, i + 2)
        if (kin.convention == "standard" and abs(np.sin(kin.alpha[i])) < 1e-3) or (
                kin.convention == "modified" and i + 1 < kin.nq and abs(np.sin(kin.alpha[i + 1])) < 1e-3):
            reason += f" (parallel axes {pair[0]},{pair[1]}: Hayati beta replaces it)"
    elif kind == "beta" and idx.isdigit():
        i = int(idx) - 1
        if abs(kin.a[i]) < 1e-9 and abs(np.sin(kin.alpha[i])) > 1e-3:
            reason += f" (a_{idx} = 0 and axes not parallel: same motion as theta)"
    elif problem.plane is not None and name == f"{problem.plane.prefix}_f":
        reason += " (plane offset shifts every distance like a base translation)"
    elif problem.plane is not None and name.startswith(problem.plane.prefix):
        reason += " (plane equation is defined up to scale: gauge)"
    return reason
