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
def tiago_kinematics(path: Path = URDF) -> KinematicModel:
    from spacearm.base.kinematics.arm_import import import_arm
    _, cfg = import_arm(path, "base_link", "arm_7_link")
    return KinematicModel.from_config(cfg)


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


def fit_tiago(registration_only: bool = False, tool_point: tuple[float, float, float] = (0.0, 0.0, 0.0),
              opts: FitOptions = FitOptions(), sigma: float = SIGMA) -> TiagoFit:
    """Identify on the training day, score every posture of the validation day."""
    kin = tiago_kinematics()
    Qt, Pt = load_session(TRAINING)
    Qv, Pv = load_session(VALIDATION)
    marker = PointModel(tool_point)
    train = Block(marker, Qt, Pt, sigma, label=TRAINING.name)
    valid = Block(marker, Qv, Pv, sigma, label=VALIDATION.name)
    em = ErrorModel.from_kinematics(kin, world=initial_registration(ErrorModel.from_kinematics(kin), [train]))
    names = CompositeProblem(em, [train], []).names
    if registration_only:
        cands = em.frame_names("world") + list(marker.extra_names)
    else:
        cands = [n for n in names if not n.startswith(em.tool_prefix + "_")]
    rep = fit_blocks(em, [train], opts, candidates=cands, validation=[valid])
    after = np.array([h.after for h in rep.held_out])
    return TiagoFit(rep, "registration only" if registration_only else "full", len(rep.result.free),
                    rep.train_position_rms, float(np.sqrt(np.mean(after ** 2))), float(after.max()))
