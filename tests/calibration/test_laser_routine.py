"""The on-orbit laser routine with in-process move/measure: it refuses a posture count that
cannot identify the model before moving the arm, and reports every held-out posture."""
from __future__ import annotations

import numpy as np
import pytest

from spacearm.controller.calibration.laser_routine import CalibrationRunError, run_laser_calibration
from spacearm.firmware_sim.laser_ranger import arm_plane_distance

STEP = np.deg2rad(25 / 3600)      # resolver step


def arm_and_ranger(st, rng):
    current = {"q": np.zeros(st.model.kin.nq)}
    plane = st.x_true[st.model.n_params:]
    true_distance = arm_plane_distance(st.model, st.x_true, plane[:3], plane[3], lambda: current["q"])
    moves = []

    def move_to(q):
        moves.append(q)
        current["q"] = np.asarray(q, float)
        return np.round(current["q"] / STEP) * STEP          # what the resolvers report

    def measure():
        h = true_distance()
        return None if h is None else h + rng.normal(0.0, 0.2e-3 / np.sqrt(10))
    return move_to, measure, moves


def test_too_few_postures_are_refused_before_the_arm_moves(laser_setup):
    move_to, measure, moves = arm_and_ranger(laser_setup, np.random.default_rng(1))
    n_free = len(laser_setup.report.kept)
    with pytest.raises(CalibrationRunError, match=f"cannot identify {n_free} parameters; use at least {n_free + 5}"):
        run_laser_calibration(laser_setup, move_to, measure, np.zeros(6), m=n_free)
    assert moves == []


def test_every_held_out_posture_is_reported(laser_setup):
    st = laser_setup
    move_to, measure, moves = arm_and_ranger(st, np.random.default_rng(2))
    result = run_laser_calibration(st, move_to, measure, np.zeros(6), m=40, n_validation=12)
    assert len(moves) == 52 and len(result.Q_validation) == len(result.validation_residuals_after) == 12
    rms = lambda r: float(np.sqrt(np.mean(r ** 2)))  # noqa: E731
    assert rms(result.validation_residuals_after) == pytest.approx(result.validation_rms_after)
    assert rms(result.validation_residuals_before) == pytest.approx(result.validation_rms_before)
    # the residuals are of the held-out readings themselves: reading minus the model's prediction
    problem = st.problem(result.Q_validation, result.h_validation, 1.0)
    assert np.allclose(result.validation_residuals_after,
                       result.h_validation - problem.predict(result.fit.x, result.Q_validation))
    assert result.validation_rms_after < 0.1 * result.validation_rms_before
