"""Identifiable (base) parameter set by rank-revealing QR with column pivoting on the data's postures.

Procedure (deterministic, never raises on a rank-deficient or nearly deficient Jacobian):
 1. The identification Jacobian on the data's own postures (rows whitened by the stated noise
    when it comes from a measurement problem), or on a well-spread random posture set.
 2. Columns scaled: to unit norm, or, when `scale` gives each parameter's plausible size, to the
    change of the (whitened) readings that an error of that size makes, so metres and radians
    compete by what they do to the data.
 3. Preference tiers, walked in order; within a tier, pivoted QR (scipy.linalg.qr,
    pivoting=True) of the columns' part orthogonal to everything kept so far. A column is kept
    while its pivot |R_kk| exceeds one tolerance: `floor` (noise units: an error of plausible
    size must move the readings by that many noise sigmas beyond what the kept parameters can
    absorb) and never below `tol` relative to the largest column (numerical rank).
    Tiers (kept first): the instrument's own placement (anchor, wire length offset, marker or
    tool point), then the registration (world frame), the tool mount frame, the D-H terms
    theta, d, a, alpha, Hayati beta, the joint compliances, the plane's coefficients, the d that beta replaces on
    parallel axes, and the plane's gauge last. So a set-up error is never absorbed into the
    arm's geometry; within a tier, exact ties follow the parameters' order.
 4. Each dropped column is explained by regressing it on the kept ones.
Because the tolerance and the tiers do not depend on the start values (only on the postures
and the noise), neither does the kept set, up to ties decided at the numerical tolerance.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg
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


def preference_tier(problem: Problem, gauge: str | None = None) -> Callable[[str], float]:
    """Keep-preference tier of a parameter name (lower is kept first; module docstring)."""
    kin = problem.model.kin
    hayati_d = set()
    for i in parallel_links(problem):
        # standard D-H: alpha_i ~ 0 means z_{i-1} || z_i, so d_i slides along the same line as
        # d_{i+1}; Hayati replaces d_i by beta_i. Modified rows carry alpha_{i-1}: the alpha on
        # joint i+1's row couples d_i and d_{i+1}; the earlier d is the one replaced.
        if kin.convention == "standard":
            hayati_d.add(f"d_{i + 1}")
        elif i >= 1:
            hayati_d.add(f"d_{i}")
    plane_prefix = problem.plane.prefix + "_" if problem.plane is not None else None
    last = ({gauge} if gauge else set()) | ({plane_prefix + "f"} if plane_prefix else set())

    def tier(name: str) -> float:
        kind = name.rsplit("_", 1)[0]
        if name in last:
            return 6
        if name in hayati_d:
            return 5
        if kind in ("theta", "d", "a", "alpha"):
            return 0
        if kind == "beta":
            return 1
        if kind == "k":
            return 2    # joint compliance: load-proportional, after the geometry it would mimic
        if plane_prefix and name.startswith(plane_prefix):
            return 4    # the laser paper keeps the plane after the arm (its 25 + 1)
        if name.startswith(problem.model.world_prefix + "_"):
            return -2   # registration of the measurement frame
        if name.startswith(problem.model.tool_prefix + "_"):
            return -1   # the tool's (camera's, marker plate's) mount on the flange
        return -3       # the instrument's own placement: anchor, wire offset, marker point
    return tier


def priority_order(problem: Problem, candidates: list[str], gauge: str | None = None) -> list[str]:
    """Candidates sorted by keep-preference (see module docstring)."""
    tier = preference_tier(problem, gauge)
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
                      Q: Array | None = None, A: Array | None = None, scale: Array | None = None,
                      floor: float = 0.0) -> IdentifiabilityReport:
    """The identifiable subset of `candidates` (default: all parameters) with reasons for drops.

    `A` (rows, len(candidates)) is a given identification Jacobian, e.g. on the data's own
    postures (see fit_checks.data_identifiability); otherwise it is evaluated on Q or random
    postures. `scale` (len(candidates),) and `floor`: see the module docstring.
    """
    candidates = list(candidates) if candidates is not None else list(problem.names)
    if A is None:
        A = identifiability_jacobian(problem, candidates, n_configs, seed, Q)
    A = np.asarray(A, float)
    norms = np.linalg.norm(A, axis=0)
    finite = np.isfinite(norms)
    top = norms[finite].max() if finite.any() else 0.0
    dropped: list[Dropped] = []
    usable = []
    for j, name in enumerate(candidates):
        if not finite[j]:
            dropped.append(Dropped(name, "its effect on the measurement is not finite here"))
        elif norms[j] <= 1e-12 * max(top, 1e-300):
            dropped.append(Dropped(name, "no effect on the measurement"))
        else:
            usable.append(j)
    names = [candidates[j] for j in usable]
    if scale is None:
        As = A[:, usable] / norms[usable]
    else:
        As = A[:, usable] * np.asarray(scale, float)[usable]
    col = {n: As[:, k] for k, n in enumerate(names)}
    s = np.linalg.svd(As, compute_uv=False) if names else np.zeros(0)
    threshold = max(floor, tol * (s[0] if s.size else 0.0) * max(As.shape) ** 0.5)
    tier = preference_tier(problem, gauge)
    kept = _pivoted_selection(col, priority_order(problem, names, gauge), threshold, tier)
    for name in names:
        if name not in kept:
            dropped.append(Dropped(name, _explain(name, col, kept, problem)))
    kept_sorted = [n for n in candidates if n in kept]
    K = np.column_stack([col[n] for n in kept_sorted]) if kept else np.zeros((A.shape[0], 0))
    sk = np.linalg.svd(K, compute_uv=False) if kept else np.array([1.0])
    pos = {n: i for i, n in enumerate(candidates)}
    dropped.sort(key=lambda d: pos[d.name])
    return IdentifiabilityReport(kept_sorted, dropped, len(kept), s, float(sk[0] / max(sk[-1], 1e-300)))


def _pivoted_selection(col: dict[str, Array], order: list[str], threshold: float,
                       tier: Callable[[str], float]) -> list[str]:
    """Walk the tiers; in each, pivoted QR of the columns' part orthogonal to the kept ones.

    Columns are nudged by their place in `order` (at most 1e-6 relative) before pivoting, so
    exactly interchangeable columns resolve in the stated order while a column with a clearly
    larger independent part still wins inside its tier."""
    if not order:
        return []
    basis = np.zeros((len(col[order[0]]), 0))
    kept: list[str] = []
    for level in sorted({tier(n) for n in order}):
        group = [n for n in order if tier(n) == level]
        M = np.column_stack([col[n] for n in group])
        for _ in range(2):                       # twice: numerically orthogonal to the basis
            M = M - basis @ (basis.T @ M)
        nudge = 1.0 - 1e-6 * np.arange(len(group)) / max(len(group), 1)
        Qm, R, piv = scipy.linalg.qr(M * nudge, mode="economic", pivoting=True)
        diag = np.abs(np.diag(R)) if R.size else np.zeros(0)
        k = 0
        while k < len(diag) and diag[k] > threshold:
            k += 1
        kept += [group[p] for p in piv[:k]]
        basis = np.column_stack([basis, Qm[:, :k]])
    return kept


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
