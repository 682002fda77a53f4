"""Calibration-study trial kinds: one seeded run of a study per trial (controller/calibration/study_trials).

    calibration_laser  the laser-ranger paper's study (O3-optimal postures, LM / LSE, Table 5)
    calibration_ekf    the EKF paper's camera-pose study (Tables 4 and 5, Figure 8)
    calibration_model  the synthetic study of one measurement model (pose, point, range, plane)

`spacearm calibrate study` runs these as campaigns and prints the papers' tables from the rows
(studies.py); a campaign file of the same kind runs through `spacearm campaign run` alike.
Success is judged on the headline figures: the first configuration count's first method.
"""
from __future__ import annotations

from typing import Any

from spacearm.offline.campaign.kinds import TrialKind, TrialOutcome, in_clone


def _outcome(numbers, min_reduction: float) -> TrialOutcome:
    before, after = numbers.figures["position_rms_before"], numbers.figures["position_rms_after"]
    reduction = 1.0 - after / before if before > 0 else 0.0
    figures = {**numbers.figures, "position_reduction": reduction}
    ok = reduction >= min_reduction
    failure = None if ok else f"position error reduced by {100 * reduction:.1f} % < {100 * min_reduction:.0f} %"
    return TrialOutcome(ok, failure, figures, numbers.timings, numbers.series)


def run_calibration_laser(params: dict[str, float], options: dict[str, Any], seed: int) -> TrialOutcome:
    in_clone()
    from spacearm.controller.calibration.study_trials import laser_trial
    opts = {**CALIBRATION_LASER.options, **options}
    numbers = laser_trial(seed, params.get("noise", 0.2e-3), tuple(int(m) for m in opts["configurations"]),
                          tuple(str(m) for m in opts["methods"]), int(opts["candidates"]), int(opts["validation"]),
                          int(opts["repetitions"]))
    return _outcome(numbers, float(opts["min_reduction"]))


CALIBRATION_LASER = TrialKind(
    "calibration_laser", run_calibration_laser, ("noise",),
    {"configurations": [50], "methods": ["lm"], "candidates": 101, "validation": 20, "repetitions": 10,
     "min_reduction": 0.9},
    "position_rms_after", "laser-ranger identification (paper study): O3-optimal postures, LM / LSE, held-out check")


def run_calibration_ekf(params: dict[str, float], options: dict[str, Any], seed: int) -> TrialOutcome:
    in_clone()
    from spacearm.controller.calibration.study_ekf import DEG
    from spacearm.controller.calibration.study_trials import ekf_trial
    opts = {**CALIBRATION_EKF.options, **options}
    numbers = ekf_trial(seed, params.get("sigma_position", 0.3e-3), params.get("sigma_rotation", 0.5 * DEG),
                        int(params.get("configurations", opts["configurations"])), int(opts["validation"]),
                        tuple(str(m) for m in opts["methods"]), int(opts["validation_seed"]),
                        bool(opts["per_posture"]))
    return _outcome(numbers, float(opts["min_reduction"]))


CALIBRATION_EKF = TrialKind(
    "calibration_ekf", run_calibration_ekf, ("sigma_position", "sigma_rotation", "configurations"),
    # validation_seed >= 0: every trial validates on the same postures (Figure 8); per_posture: box-plot series
    {"configurations": 50, "validation": 200, "methods": ["ekf_cov"], "min_reduction": 0.5,
     "validation_seed": -1, "per_posture": False},
    "position_rms_after", "camera-pose identification (EKF paper study): LSE, EKF tunings, LM")


def run_calibration_model(params: dict[str, float], options: dict[str, Any], seed: int) -> TrialOutcome:
    in_clone()
    from spacearm.controller.calibration.study_models import MODELS
    from spacearm.controller.calibration.study_trials import model_trial
    opts = {**CALIBRATION_MODEL.options, **options}
    if opts["model"] not in MODELS:
        raise ValueError(f"options.model: expected one of {', '.join(MODELS)}, got {opts['model']!r}")
    numbers = model_trial(opts["model"], seed, int(opts["postures"]), int(opts["validation"]),
                          params.get("noise_scale", 1.0))
    ratio, limit = numbers.figures["error_to_floor"], float(opts["max_error_to_floor"])
    failure = None if ratio <= limit else f"validation error {ratio:.2f} x the Cramer-Rao floor > {limit:g}"
    return TrialOutcome(failure is None, failure, numbers.figures, numbers.timings, numbers.series)


CALIBRATION_MODEL = TrialKind(
    "calibration_model", run_calibration_model, ("noise_scale",),
    {"model": "pose", "postures": 60, "validation": 200, "max_error_to_floor": 1.5},
    "error_to_floor", "synthetic calibration study of one measurement model: fit, validation error vs its floor")
