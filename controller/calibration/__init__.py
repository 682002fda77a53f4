"""Kinematic identification core: error model, residuals, identifiability, solvers, design, validation.

Typical use::

    em = ErrorModel.from_kinematics(load_model("configs/arm/ssrms_7dof.toml"))
    pr = Problem(em, "pose", Q, measured_poses, em.dh_names(with_beta=False), sigma=sig)
    rep = find_identifiable(pr)                    # kept / dropped with reasons
    res = lm(Problem(..., free=rep.kept, ...))     # or lse(...), ekf(..., EKFTuning.paper(pr))
    stats = compare_poses(T_true, em.poses(res.x[:em.n_params], Q_valid))

Measurement files of any instrument mix (pose, 3-D point, range, plane)::

    blocks = [Block(PointModel((0, 0, 0.05)), Q, xyz, 1e-4), Block(RangeModel(anchor), Q2, L, 1e-4)]
    report = fit_blocks(em, blocks, FitOptions(holdout=0.2))   # report.verdict.ok before applying
"""
from spacearm.controller.calibration.composite import Block, CompositeProblem
from spacearm.controller.calibration.errormodel import ErrorModel
from spacearm.controller.calibration.measurement_models import PlaneModel, PointModel, PoseModel, RangeModel
from spacearm.controller.calibration.identifiability import (Dropped, IdentifiabilityReport,
                                                    find_identifiable)
from spacearm.controller.calibration.observability import (Selection, board_in_view, configuration_blocks,
                                                  laser_ok, observability, random_subsets_best,
                                                  select_configurations)
from spacearm.controller.calibration.residuals import PlaneTarget, Problem, laser_distance, rotvec_batch
from spacearm.controller.calibration.solvers import CalibrationResult, EKFTuning, ekf, lm, lse
from spacearm.controller.calibration.trusted_fit import FitOptions, FitReport, fit_blocks
from spacearm.controller.calibration.validation import ValidationStats, compare_poses, mean_stats

__all__ = [
    "ErrorModel", "Problem", "PlaneTarget", "laser_distance", "rotvec_batch",
    "find_identifiable", "IdentifiabilityReport", "Dropped",
    "lse", "lm", "ekf", "EKFTuning", "CalibrationResult",
    "observability", "select_configurations", "random_subsets_best", "configuration_blocks",
    "laser_ok", "board_in_view", "Selection",
    "compare_poses", "ValidationStats", "mean_stats",
    "Block", "CompositeProblem", "PoseModel", "PointModel", "RangeModel", "PlaneModel",
    "FitOptions", "FitReport", "fit_blocks",
]
