"""The on-orbit laser-ranger calibration routine (laser-ranger paper, Sections 3-5) on a live arm.

The routine only needs two things from the outside, so it runs unchanged against the daemon
(through the console's command API) or any other arm:

    move_to(q) -> q_measured     jerk-limited move, wait until settled, resolver angles (rad)
    measure() -> h | None        averaged laser distance (m), None when the beam misses

Steps: candidate postures whose beam hits the *nominal* plane within range; the O3-optimal
m of them (greedy + exchange) for identification plus independent validation postures;
visit them in nearest-neighbour order (the joints are slow: 5 deg/s); identify the
identifiable D-H parameters and the plane's tilt by weighted Levenberg-Marquardt; report the
held-out distance residuals before and after. `calibration_section` and
`write_calibrated_arm` turn the result into the arm file's [calibration] table.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable, Optional

import numpy as np
from numpy.typing import NDArray

from spacearm.controller.calibration.observability import configuration_blocks, laser_ok, sample_valid, select_configurations
from spacearm.controller.calibration.solvers import CalibrationResult, lm
from spacearm.controller.calibration.study_laser import LaserSetup
from spacearm.base.config.arm import Calibration

Array = NDArray[np.float64]
MoveTo = Callable[[Array], Array]
Measure = Callable[[], Optional[float]]
Progress = Callable[[str, int, int], None]


class CalibrationRunError(RuntimeError):
    """The routine cannot produce a trustworthy model (too few valid readings, no convergence)."""


@dataclass
class LaserRunResult:
    Q: Array                      # identification postures actually used (measured angles)
    h: Array                      # their distances, m
    Q_validation: Array
    h_validation: Array
    skipped: int                  # postures where the beam missed the real plane
    fit: CalibrationResult
    errors: dict[str, float]      # identified parameter - nominal, by name (m / rad)
    residual_rms: float           # identification residual RMS, m
    validation_rms_before: float  # held-out distance residual RMS with the nominal model, m
    validation_rms_after: float   # the same with the identified model, m
    seconds: float
    log: list[str] = field(default_factory=list)
    validation_residuals_before: Array = field(default_factory=lambda: np.zeros(0))  # per held-out posture, m
    validation_residuals_after: Array = field(default_factory=lambda: np.zeros(0))


def nearest_neighbour_order(Q: Array, q_start: Array) -> Array:
    """Visit order of the rows of Q, each time the closest (max joint travel) unvisited one."""
    left = list(range(len(Q)))
    order, q = [], np.asarray(q_start, float)
    while left:
        travel = [np.max(np.abs(Q[i] - q)) for i in left]
        k = left.pop(int(np.argmin(travel)))
        order.append(k)
        q = Q[k]
    return np.array(order, dtype=int)


def plan_postures(setup: LaserSetup, m: int, n_candidates: int, n_validation: int,
                  rng: np.random.Generator, h_range: tuple[float, float]) -> tuple[Array, Array]:
    """Identification (O3-optimal m of n_candidates) and validation postures, from the nominal
    model only (the controller does not know the truth)."""
    kin = setup.model.kin
    probe = setup.problem(np.zeros((1, kin.nq)), np.zeros(1), 1.0)
    ok = lambda Q: laser_ok(probe, Q, h_range=h_range)  # noqa: E731
    sampler = lambda n, r: kin.random_configurations(n, r, margin=0.1)  # noqa: E731
    candidates = sample_valid(sampler, ok, n_candidates, rng)
    blocks = configuration_blocks(setup.problem(candidates, np.zeros(len(candidates)), 1.0), candidates)
    chosen = candidates[select_configurations(blocks, m, "O3").indices]
    validation = sample_valid(sampler, ok, n_validation, rng)
    return chosen, validation


def run_laser_calibration(setup: LaserSetup, move_to: MoveTo, measure: Measure, q_start: Array, *,
                          m: int = 50, n_candidates: int = 101, n_validation: int = 20,
                          sigma: float = 0.2e-3 / np.sqrt(10), seed: int = 0,
                          h_range: tuple[float, float] = (0.1, 2.8),
                          progress: Progress | None = None) -> LaserRunResult:
    t0 = time.monotonic()
    n_free = len(setup.report.kept)
    if m < n_free + 5:              # say so before an hour of moves, not after
        raise CalibrationRunError(f"{m} identification postures cannot identify {n_free} parameters; "
                                  f"use at least {n_free + 5}")
    rng = np.random.default_rng(seed)
    chosen, validation = plan_postures(setup, m, n_candidates, n_validation, rng, h_range)
    postures = np.vstack([chosen, validation])
    is_validation = np.r_[np.zeros(len(chosen), bool), np.ones(len(validation), bool)]
    order = nearest_neighbour_order(postures, q_start)
    log: list[str] = []
    Q, h, Qv, hv = [], [], [], []
    skipped = 0
    for step, k in enumerate(order, 1):
        q_measured = move_to(postures[k])
        distance = measure()
        if progress is not None:
            progress("validation" if is_validation[k] else "identification", step, len(order))
        if distance is None:
            skipped += 1
            log.append(f"posture {step}: beam missed the plane, skipped")
            continue
        (Qv if is_validation[k] else Q).append(q_measured)
        (hv if is_validation[k] else h).append(distance)
    if len(Q) < n_free + 5:
        raise CalibrationRunError(f"only {len(Q)} valid identification readings for {n_free} parameters "
                                  f"({skipped} postures missed the plane); need at least {n_free + 5}")
    Q, h, Qv, hv = (np.array(a, float) for a in (Q, h, Qv, hv))
    problem = setup.problem(Q, h, sigma)
    fit = lm(problem)
    if not np.all(np.isfinite(fit.x)):
        raise CalibrationRunError(f"identification diverged ({fit.status})")
    nominal = problem.nominal()
    errors = {name: float(fit.x[i] - nominal[i]) for i, name in enumerate(problem.names)
              if name in problem.free and abs(fit.x[i] - nominal[i]) > 0.0}
    residual = h - problem.predict(fit.x, Q)
    held_before = hv - problem.predict(nominal, Qv) if len(Qv) else np.zeros(0)
    held_after = hv - problem.predict(fit.x, Qv) if len(Qv) else np.zeros(0)
    rms = lambda r: float(np.sqrt(np.mean(r ** 2))) if len(r) else float("nan")  # noqa: E731
    return LaserRunResult(Q, h, Qv, hv, skipped, fit, errors, rms(residual), rms(held_before), rms(held_after),
                          time.monotonic() - t0, log, held_before, held_after)


def calibration_section(setup: LaserSetup, result: LaserRunResult, data: str = "") -> Calibration:
    """The arm file's [calibration] table from an identification (plane terms stay out: the
    plane is the target, not the arm)."""
    n = setup.model.kin.nq

    def per_joint(kind: str) -> list[float]:
        return [result.errors.get(f"{kind}_{i + 1}", 0.0) for i in range(n)]

    return Calibration(
        method="laser-ranger distance to a plane, weighted Levenberg-Marquardt",
        date=datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"), data=data,
        configurations=len(result.Q), residual_rms=result.residual_rms,
        validation_rms_before=result.validation_rms_before, validation_rms_after=result.validation_rms_after,
        dtheta=per_joint("theta"), dalpha=per_joint("alpha"), da=per_joint("a"), dd=per_joint("d"),
        dbeta=per_joint("beta"))


def write_calibrated_arm(nominal_arm: Path, calibration: Calibration, out: Path, command: str = "calibrate laser",
                         comments: list[str] = ()) -> None:
    """Copy of the nominal arm file with the [calibration] table appended (the nominal rows stay
    as they are; the model adds the corrections). `command` names the routine that identified
    it; `comments` (lines without '#') follow the table as provenance."""
    text = Path(nominal_arm).read_text()
    if any(line.strip() == "[calibration]" for line in text.splitlines()):
        raise CalibrationRunError(f"{nominal_arm} already has a [calibration] table; start from the nominal file")

    def value(v) -> str:
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, list):
            return "[" + ", ".join(repr(float(x)) for x in v) + "]"
        return repr(v)

    lines = ["", f"# Identified by `spacearm {command} --apply`; remove this table to fly the nominal model.",
             "[calibration]"]
    lines += [f"{key} = {value(v)}" for key, v in calibration.model_dump().items() if v is not None]
    lines += [f"# {c}" for c in comments]
    Path(out).write_text(text.rstrip("\n") + "\n" + "\n".join(lines) + "\n")
