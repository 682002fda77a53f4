"""Real motion-capture data of a TIAGo arm (../shared/data/tiago_mocap): identify on one day, validate on another.

The arm is imported from the data's own URDF (prismatic torso lift + 7 revolute joints, chain
base_link -> arm_7_link); the tracked point is marker 1 on the wrist, whose place on the last link
is unknown; the motion-capture frame is not the base frame, so the registration (6) is estimated
too. The fit is the general pipeline of `spacearm calibrate fit --register` with the other day's
file as `--validate`. Errors are RMS of the marker-1 position error norm (FIGAROH's definition).
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from spacearm.base.kinematics import KinematicModel
from spacearm.base.paths import SHARED_DATA
from spacearm.controller.calibration.composite import Block, CompositeProblem
from spacearm.controller.calibration.errormodel import ErrorModel
from spacearm.controller.calibration.fit_setup import initial_registration
from spacearm.controller.calibration.joint_load import JointLoad
from spacearm.controller.calibration.measurement_models import PointModel
from spacearm.controller.calibration.trusted_fit import FitOptions, FitReport, fit_blocks

Array = NDArray[np.float64]
DATA = SHARED_DATA / "tiago_mocap"
URDF = DATA / "tiago_48_schunk.urdf"
TRAINING = DATA / "qualisys_2021-11-30_static_postures.csv"
VALIDATION = DATA / "qualisys_2021-11-26_static_postures.csv"
JOINTS = ("torso_lift_joint",) + tuple(f"arm_{i}_joint" for i in range(1, 8))
SIGMA = 1e-3     # m: marker noise (~0.3 mm) plus what a rigid geometric model cannot describe


@lru_cache(maxsize=None)
def _tiago(path: Path = URDF) -> tuple[KinematicModel, JointLoad]:
    from spacearm.base.kinematics.arm_import import import_arm
    _, cfg = import_arm(path, "base_link", "arm_7_link")
    kin = KinematicModel.from_config(cfg)
    return kin, JointLoad.from_config(kin, cfg.links)


def tiago_kinematics(path: Path = URDF) -> KinematicModel:
    return _tiago(path)[0]


def tiago_load(path: Path = URDF) -> JointLoad:
    """Gravity load per joint from the URDF's inertials (the links up to arm_7_link)."""
    return _tiago(path)[1]


def load_session(path: Path, marker: int = 1) -> tuple[Array, Array]:
    """Joint values (N, 8: m, rad) and one marker's positions (N, 3: m) of one session's file."""
    with Path(path).open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    Q = np.array([[float(r[j]) for j in JOINTS] for r in rows])
    P = np.array([[float(r[f"{c}{marker}"]) for c in "xyz"] for r in rows])
    return Q, P


@dataclass
class TiagoFit:
    report: FitReport
    label: str
    parameters: int
    train_rms: float        # m
    validation_rms: float   # m
    validation_max: float   # m
    model: ErrorModel | None = None


def validation_day_registration(fit: TiagoFit, sigma: float = SIGMA) -> tuple[float, Array]:
    """Diagnostic only, never a reported figure: the validation RMS (m) after fitting the six
    registration parameters (mocap frame <- base) to the validation day itself, the calibrated arm
    held fixed, and that day's mean position error (m, x y z) before. It measures how much of the
    validation error is the motion-capture frame moved between the two days."""
    from spacearm.controller.calibration.solvers import lm
    Qv, Pv = load_session(VALIDATION)
    em = fit.model
    vp = CompositeProblem(em, [Block(PointModel(), Qv, Pv, sigma)], em.frame_names("world"), fit.report.result.x)
    mean = vp.position_errors(vp.x0)[0].mean(axis=0)
    return _rms_distance(vp.position_errors(lm(vp).x)[0]), mean


def _rms_distance(e: Array) -> float:
    """RMS of the lengths of position errors (N, 3)."""
    return float(np.sqrt(np.mean(np.sum(e ** 2, axis=1))))


def day_to_day_repeatability(tol: float = 1e-3) -> tuple[Array, float, float]:
    """Diagnostic (it reads both days; never a reported figure): the validation day's rows that
    repeat an identification-day posture (every joint within `tol`, rad or m), and marker 1's RMS
    position difference between the two measurements of those postures (m), raw and after the
    best rigid transform between the two days' motion-capture frames. What is left after that
    transform is what the robot, the markers and the cameras do not repeat: no model of the arm
    predicts the other day better at those postures."""
    from spacearm.controller.calibration.instrument_start import kabsch
    Qt, Pt = load_session(TRAINING)
    Qv, Pv = load_session(VALIDATION)
    gap = np.abs(Qt[:, None, :] - Qv[None, :, :]).max(axis=2)
    hit = gap.min(axis=1) <= tol
    rows = gap.argmin(axis=1)[hit]
    A, B = Pt[hit], Pv[rows]
    T = kabsch(A, B)
    moved = A @ T[:3, :3].T + T[:3, 3]
    return rows, _rms_distance(B - A), _rms_distance(B - moved)


def training_loo(fit: TiagoFit, sigma: float = SIGMA) -> float:
    """The identification day's leave-one-posture-out position RMS of `fit` (m), linearised at its
    estimate with its priors: the criterion the group selection minimises (trusted_fit's
    loo_position_rms), so that a bench can set it beside the other day's figure."""
    from spacearm.controller.calibration.trusted_fit import loo_position_rms
    Qt, Pt = load_session(TRAINING)
    rep = fit.report
    problem = CompositeProblem(fit.model, [Block(PointModel(), Qt, Pt, sigma)], rep.result.free)
    return loo_position_rms(problem, rep.result.x, rep.priors)


def fit_tiago(registration_only: bool = False, tool_point: tuple[float, float, float] = (0.0, 0.0, 0.0),
              opts: FitOptions = FitOptions(), sigma: float = SIGMA, elastic: bool = False) -> TiagoFit:
    """Identify on the training day, score every posture of the validation day; `elastic`: with a
    compliance per joint under its gravity load among the candidates (FIGAROH's non-geometric terms)."""
    kin = tiago_kinematics()
    Qt, Pt = load_session(TRAINING)
    Qv, Pv = load_session(VALIDATION)
    marker = PointModel(tool_point)
    train = Block(marker, Qt, Pt, sigma, label=TRAINING.name)
    valid = Block(marker, Qv, Pv, sigma, label=VALIDATION.name)
    em = ErrorModel.from_kinematics(kin, world=initial_registration(ErrorModel.from_kinematics(kin), [train]),
                                    load=tiago_load() if elastic else None)
    names = CompositeProblem(em, [train], []).names
    if registration_only:
        cands = em.frame_names("world") + list(marker.extra_names)
    else:
        cands = [n for n in names if not n.startswith(em.tool_prefix + "_")]
    rep = fit_blocks(em, [train], opts, candidates=cands, validation=[valid])
    after = np.array([h.after for h in rep.held_out])
    label = "registration only" if registration_only else "full + elasticity" if elastic else "full"
    if opts.select_groups and not registration_only:
        label += ", groups by CV"
    return TiagoFit(rep, label, len(rep.result.free),
                    rep.train_position_rms, float(np.sqrt(np.mean(after ** 2))), float(after.max()), em)
