"""A training-day check of the TIAGo model from the orientation of the wrist's marker plate.

The four markers are one rigid plate (their distances agree to 1 um), so every posture of the
identification day also gives the plate's orientation, which the marker-1 fit never uses. Fitting
the rigid model to the plate's full pose and resolving the orientation left over onto the three
wrist joints' angles says which joint the rigid model gets wrong and how: on 2021-11-30 arm_6
(joint 7) is off by ~12 mrad RMS, in step with its gravity torque (correlation ~0.7) - the
deflection of a soft drive, the joint compliance k_7 that the marker-1 fit then estimates. Only
the identification day is read.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from spacearm.controller.calibration.composite import Block, CompositeProblem
from spacearm.controller.calibration.errormodel import ErrorModel
from spacearm.controller.calibration.group_selection import dh_group
from spacearm.controller.calibration.instrument_start import kabsch
from spacearm.controller.calibration.measurement_models import PoseModel
from spacearm.controller.calibration.tiago_mocap import TRAINING, TiagoFit, load_session, tiago_load
from spacearm.controller.calibration.trusted_fit import FitOptions, fit_blocks

Array = NDArray[np.float64]
WRIST = (5, 6, 7)                    # joint indices of arm_5, arm_6, arm_7 (0: the torso lift)
SIGMA_POSE = (1e-3,) * 3 + (5e-3,) * 3   # m, rad: marker 1's model error and the plate's orientation
MAX_WRIST_CONDITION = 100.0


@dataclass(frozen=True)
class PlateCheck:
    orientation_rms: float           # rad, the plate's orientation left by the rigid pose fit
    wrist_rms: tuple[float, ...]     # rad, that residual as angle errors of arm_5, arm_6, arm_7
    torque_correlation: tuple[float, ...]   # of each wrist joint's angle error with its gravity torque
    used: int                        # postures resolved onto the wrist
    singular: int                    # postures left out: the wrist too near its singularity to split it
    torque_slope: tuple[float, ...]  # rad/(N m): least-squares slope of each angle error on its torque


def plate_poses(path: Path = TRAINING) -> tuple[Array, Array]:
    """Joint values (N, 8) and the plate's pose (N, 4, 4) in the motion-capture frame: origin at
    marker 1, axes those of the capture frame at the first posture (the markers' layout there)."""
    Q = load_session(path, 1)[0]
    M = np.stack([load_session(path, m)[1] for m in (1, 2, 3, 4)], axis=1)
    layout = M[0] - M[0, 0]
    return Q, np.array([kabsch(layout, m) for m in M])


def plate_check(fit: TiagoFit) -> PlateCheck:
    """Fit the rigid model with `fit`'s D-H kinds, registration and the plate's mount to the plate's
    pose on the identification day and resolve the orientation left onto the wrist's angles. Give
    it a rigid fit: a compliance is what this looks for."""
    em, x = fit.model, fit.report.result.x
    Q, T = plate_poses()
    # The plate's mount on the flange, from the marker-1 fit's arm: the average of flange^-1 plate.
    D = np.linalg.inv(em.poses(x[:em.n_params], Q)) @ T
    U, _, Vt = np.linalg.svd(D[:, :3, :3].sum(axis=0))
    tool = np.eye(4)
    tool[:3, :3], tool[:3, 3] = U @ Vt, D[:, :3, 3].mean(axis=0)
    rigid = ErrorModel.from_kinematics(em.kin, world=em.world_nominal, tool=tool)
    x0 = rigid.nominal.copy()
    arm = [n for n in em.names if n in rigid.names and not n.startswith(em.tool_prefix + "_")]
    x0[rigid.index(arm)] = x[em.index(arm)]
    block = Block(PoseModel(), Q, T, np.array(SIGMA_POSE), label="plate")
    # The fit's D-H kinds (its dropped groups stay out); the pose data decide what is identifiable.
    dropped = set(fit.report.selection.dropped) if fit.report.selection else set()
    cands = [n for n in rigid.names if dh_group(n) not in dropped]
    rep = fit_blocks(rigid, [block], FitOptions(holdout=0.0, starts=False), candidates=cands, x0=x0)
    problem = CompositeProblem(rigid, [block], rep.result.free, x0)
    w = problem.block_residuals(rep.result.x, jacobian=False)[0][0][:, 3:]
    _, J = rigid.poses_and_jacobian(rep.result.x[:rigid.n_params], Q)
    cols = rigid.index([f"theta_{j + 1}" for j in WRIST])
    # Per posture, the wrist angles that turn the plate as the residual does.
    # Postures near the wrist's singularity (two axes aligned) cannot split the residual: left out.
    A = J[:, 3:][:, :, cols]
    ok = np.linalg.cond(A) < MAX_WRIST_CONDITION
    dq = np.array([np.linalg.solve(A[i], w[i]) for i in np.flatnonzero(ok)])
    tau = tiago_load().torques(Q[ok])[:, list(WRIST)]
    return PlateCheck(float(np.sqrt(np.mean(np.sum(w ** 2, axis=1)))),
                      tuple(float(v) for v in np.sqrt(np.mean(dq ** 2, axis=0))),
                      tuple(float(np.corrcoef(dq[:, k], tau[:, k])[0, 1]) for k in range(len(WRIST))),
                      int(ok.sum()), int(len(Q) - ok.sum()),
                      tuple(float(np.polyfit(tau[:, k], dq[:, k], 1)[0]) for k in range(len(WRIST))))
