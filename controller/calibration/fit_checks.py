"""Checks that keep a calibration fit honest: identifiability on the data's own postures,
parameter groups with priors and bounds, and the physical-plausibility verdict.

A fit that did not converge, moved a parameter beyond its stated bound, left residuals far above
the stated noise, or made held-out postures worse is *rejected* with one line per reason; the
caller must not write such a result to an arm file.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from spacearm.controller.calibration.composite import CompositeProblem
from spacearm.controller.calibration.errormodel import COMPLIANCE, prismatic_joints
from spacearm.controller.calibration.identifiability import IdentifiabilityReport, find_identifiable

Array = NDArray[np.float64]
DH_KINDS = ("theta", "d", "a", "alpha", "beta")
GROUPS = ("joint_angle", "joint_length", "joint_compliance", "frame_length", "frame_angle", "plane")


def group_of(name: str) -> str:
    """Parameter group: D-H angles/lengths, frame (registration, tool, anchor) lengths/angles, plane."""
    head, _, tail = name.rpartition("_")
    if head in DH_KINDS:
        return "joint_length" if head in ("a", "d") else "joint_angle"
    if head == COMPLIANCE and tail.isdigit():
        return "joint_compliance"
    if tail in ("nx", "ny", "nz") or (tail == "f" and head.startswith("plane")):
        return "plane"
    if tail in ("x", "y", "z", "tx", "ty", "tz", "ax", "ay", "az", "l0"):
        return "frame_length"
    return "frame_angle"


@dataclass(frozen=True)
class Bounds:
    """Largest physically plausible correction per group (SI). A fit beyond them is rejected.
    Joint angles: 5 deg (a real TIAGo's arm_5 zero is ~3 deg off, FIGAROH finds the same).
    Joint compliance: sized per joint by instrument_bounds as a deflection (the joint-angle or
    joint-length bound under the joint's largest gravity load in the data), since a small wrist
    drive gives tens of times more per N m than a shoulder; `joint_compliance` (1e-3 rad/(N m))
    only where the data put no load on the joint."""
    joint_angle: float = np.radians(5.0)
    joint_length: float = 0.05
    joint_compliance: float = 1e-3
    frame_length: float = 0.10
    frame_angle: float = np.radians(10.0)
    plane: float = 0.5
    by_name: tuple[tuple[str, float], ...] = ()     # per parameter, e.g. an instrument's own scale

    def of(self, name: str) -> float:
        for n, b in self.by_name:
            if n == name:
                return float(b)
        return float(getattr(self, group_of(name)))


@dataclass(frozen=True)
class Priors:
    """Regularisation: Gaussian prior sigma per group (inf = none), around the starting values;
    `by_prefix` overrides it for parameters whose name starts with a prefix (e.g. a surveyed
    anchor: ("wire_a", 0.002)), the longest matching prefix winning."""
    joint_angle: float = np.inf
    joint_length: float = np.inf
    joint_compliance: float = np.inf
    frame_length: float = np.inf
    frame_angle: float = np.inf
    plane: float = np.inf
    by_prefix: tuple[tuple[str, float], ...] = ()

    def sigma(self, name: str) -> float:
        hits = [(len(p), s) for p, s in self.by_prefix if name.startswith(p)]
        return float(max(hits)[1]) if hits else float(getattr(self, group_of(name)))

    def sigmas(self, names: list[str]) -> Array:
        return np.array([self.sigma(n) for n in names], float)

    @property
    def any(self) -> bool:
        return any(np.isfinite(getattr(self, g)) for g in GROUPS) or bool(self.by_prefix)


def default_gauge(problem: CompositeProblem) -> str | None:
    """The plane coefficient that fixes the plane equation's scale (largest nominal component)."""
    for b in problem.blocks:
        gauge = getattr(b.model, "gauge", None)
        if gauge is not None:
            return gauge()
    return None


# An instrument's placement may move by this fraction of its own scale (anchor or registration
# distance from the base plus the arm's reach), not by a fixed 100 mm: a far anchor is placed
# less precisely by hand than a near one.
INSTRUMENT_RELATIVE_BOUND = 0.25


def instrument_bounds(problem: CompositeProblem, bounds: Bounds) -> Bounds:
    """`bounds` with the instrument's and registration's length parameters scaled to their own size
    and each joint compliance to the deflection it may cause (compliance_bounds)."""
    reach = float(getattr(problem.model.kin, "reach", 1.0))
    x0 = problem.x0
    extra: list[tuple[str, float]] = []
    for b, sl in zip(problem.blocks, problem.extra_slices):
        names = list(b.model.extra_names)
        values = x0[sl]
        own = float(np.linalg.norm(values[:3])) if names and names[0].endswith("_ax") else 0.0
        for n in names:
            if group_of(n) == "frame_length":
                extra.append((n, max(bounds.frame_length, INSTRUMENT_RELATIVE_BOUND * (own + reach))))
    world = problem.model.pre[:3, 3]
    for n in problem.model.frame_names("world")[:3]:
        extra.append((n, max(bounds.frame_length, INSTRUMENT_RELATIVE_BOUND * (float(np.linalg.norm(world)) + reach))))
    extra += compliance_bounds(problem, bounds)
    given = dict(bounds.by_name)
    return dataclasses.replace(bounds, by_name=tuple((n, given.get(n, v)) for n, v in extra)
                               + tuple((n, v) for n, v in bounds.by_name if n not in dict(extra)))


def compliance_bounds(problem: CompositeProblem, bounds: Bounds) -> list[tuple[str, float]]:
    """Per joint compliance k_j: the one that deflects the joint by the joint-angle bound (joint-length
    bound, prismatic) under its largest gravity load over the problem's postures. A bound on what
    the joint does, not a universal stiffness: TIAGo's arm_6 carries ~1 N m and gives ~0.03 rad/(N m)
    on real data, thirty times a fixed 1e-3 that kept it out of the fit. Joints the data do not
    load keep `bounds.joint_compliance` (their column is zero: never estimated)."""
    load = problem.model.load
    if load is None:
        return []
    Q = np.concatenate([b.Q for b in problem.blocks])
    if not len(Q):
        return []
    peak = np.abs(load.torques(Q)).max(axis=0)
    prismatic = prismatic_joints(problem.model.kin)
    out = []
    for j, t in enumerate(peak):
        name = f"{COMPLIANCE}_{j + 1}"
        if name in problem.names and t > 0.0:
            out.append((name, (bounds.joint_length if prismatic[j] else bounds.joint_angle) / float(t)))
    return out


# An error of plausible size (its bound) must move the whitened readings by this many noise
# sigmas, beyond what the parameters kept before it can absorb, to be estimated at all: the
# usual 3-sigma detection limit.
DETECTABLE_SIGMAS = 3.0


def data_identifiability(problem: CompositeProblem, candidates: list[str], tol: float = 1e-6,
                         bounds: "Bounds | None" = None) -> IdentifiabilityReport:
    """Identifiable subset of `candidates` on the problem's own postures (at its start values):
    pivoted QR of the whitened Jacobian, columns scaled by each parameter's plausible size, one
    tolerance in noise units (DETECTABLE_SIGMAS)."""
    _, A = problem.residual_and_jacobian(problem.x0)
    idx = [problem.names.index(n) for n in candidates]
    bounds = bounds or Bounds()
    scale = np.array([bounds.of(n) for n in candidates])
    return find_identifiable(problem, candidates, tol=tol, gauge=default_gauge(problem),
                             A=A[:, 0, idx], scale=scale, floor=DETECTABLE_SIGMAS)


@dataclass
class WeakDirection:
    sigma_ratio: float            # smallest / largest singular value of the scaled Jacobian
    parameters: dict[str, float]  # largest components of the weakest direction


def weakest_direction(problem: CompositeProblem, free: list[str]) -> WeakDirection:
    """The worst-determined combination of the free parameters on the data (unit-norm columns)."""
    _, A = problem.residual_and_jacobian(problem.x0)
    idx = [problem.names.index(n) for n in free]
    G = A[:, 0, idx]
    G = G / np.maximum(np.linalg.norm(G, axis=0), 1e-300)
    _, s, Vt = np.linalg.svd(G, full_matrices=False)
    v = Vt[-1]
    top = np.argsort(-np.abs(v))[:4]
    return WeakDirection(float(s[-1] / s[0]), {free[k]: float(v[k]) for k in top if abs(v[k]) > 0.1})


HELD_OUT_TOLERANCE = 0.01


NEGATIVE_COMPLIANCE = 0.1     # of a compliance's bound: below minus this, physically impossible


@dataclass
class Verdict:
    ok: bool
    reasons: list[str] = field(default_factory=list)

    def message(self) -> str:
        return "plausible" if self.ok else "fit rejected: " + "; ".join(self.reasons)


def plausibility(status: str, message: str, names: list[str], corrections: Array, bounds: Bounds,
                 train_noise_ratio: float, held_noise_ratio: float | None,
                 held_before: float | None, held_after: float | None,
                 max_noise_ratio: float = 3.0) -> Verdict:
    """Verdict on a finished fit (noise ratios: RMS of the whitened residuals, 1 = as stated)."""
    reasons = []
    if status != "converged":
        reasons.append(f"solver did not converge ({status}: {message})")
    if not np.all(np.isfinite(corrections)):
        reasons.append("estimate is not finite")
    else:
        over = [(n, c, bounds.of(n)) for n, c in zip(names, corrections) if abs(c) > bounds.of(n)]
        for n, c, b in sorted(over, key=lambda t: -abs(t[1]) / t[2])[:4]:
            reasons.append(f"{n} moved by {format_value(n, c)}, beyond its bound {format_value(n, b)}")
        if len(over) > 4:
            reasons.append(f"{len(over) - 4} more parameters beyond their bounds")
        # A joint that gives way against its load is no joint: a negative compliance deflecting it
        # visibly (a tenth of its bound) means the model is wrong there, whatever the fit gains.
        for n, c in zip(names, corrections):
            if group_of(n) == "joint_compliance" and c < -NEGATIVE_COMPLIANCE * bounds.of(n):
                reasons.append(f"{n} is {format_value(n, c)}: a joint cannot be negatively compliant "
                               f"(the model is wrong here)")
    if not np.isfinite(train_noise_ratio) or train_noise_ratio > max_noise_ratio:
        reasons.append(f"fit residuals are {train_noise_ratio:.1f}x the stated noise (limit {max_noise_ratio:g}x): "
                       "the measurement model does not describe the data")
    if held_noise_ratio is not None and not held_noise_ratio <= max_noise_ratio:
        reasons.append(f"held-out residuals are {held_noise_ratio:.1f}x the stated noise (limit {max_noise_ratio:g}x)")
    # When the start already fits to the noise (the set-up estimated from the data), the fit can
    # only match it: growth within HELD_OUT_TOLERANCE is the held-out set's own sampling noise.
    if held_before is not None and held_after is not None and not held_after <= held_before * (1 + HELD_OUT_TOLERANCE):
        reasons.append(f"held-out error grew from {held_before * 1e3:.3f} to {held_after * 1e3:.3f} mm")
    return Verdict(not reasons, reasons)


def format_value(name: str, value: float, unit_angle: str = "deg") -> str:
    """A parameter value in readable units: mm for lengths, deg (or mrad) for angles."""
    g = group_of(name)
    if g in ("joint_length", "frame_length"):
        return f"{value * 1e3:.4g} mm"
    if g == "plane":
        return f"{value:.4g}"
    if g == "joint_compliance":
        return f"{value:.4g} rad/(N m)"
    return f"{value * 1e3:.4g} mrad" if unit_angle == "mrad" else f"{np.degrees(value):.4g} deg"
