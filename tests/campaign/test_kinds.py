"""Trial kinds: each runs one trial from a seed; seed-determined kinds repeat exactly."""
from __future__ import annotations

import pytest

from spacearm.offline.campaign.kinds import KINDS

pytestmark = pytest.mark.slow

CHEAP = {"insertion": {"max_cycles": 1500}, "calibration_laser": {"configurations": [30]},
         "calibration_ekf": {"configurations": 30, "validation": 50}, "calibration_model": {"model": "range"},
         "diagnosis": {"duration": 15.0}}
PARAMS = {"insertion": {"lateral_radius": 0.004, "lateral_phase": 2.0, "tilt_angle": 0.01, "tilt_axis": 1.0},
          "calibration_laser": {"noise": 0.3e-3}, "calibration_ekf": {"sigma_position": 0.5e-3},
          "calibration_model": {"noise_scale": 1.5}, "diagnosis": {"effects": 2}}


@pytest.mark.parametrize("kind", sorted(CHEAP))
def test_a_trial_is_a_function_of_its_parameters_and_seed(kind):
    run = KINDS[kind].run
    first = run(PARAMS[kind], CHEAP[kind], 12345)
    again = run(PARAMS[kind], CHEAP[kind], 12345)
    assert first.figures and first.figures == again.figures and first.success == again.success
    assert first.series == again.series and first.labels == again.labels
    assert KINDS[kind].worst in first.figures
    if kind != "insertion":      # the start error is the insertion's only randomness
        other = run(PARAMS[kind], CHEAP[kind], 54321)
        assert other.figures != first.figures


def test_checkout_soak_runs_over_a_bus_of_its_own():
    outcome = KINDS["checkout"].run({}, {}, 1)
    assert outcome.success, outcome.failure
    assert outcome.figures["final_position_error"] < 1e-3 and outcome.timings["cycles"] > 100


def test_approach_from_a_random_start_converges_on_a_bus_of_its_own():
    start = {"start_x": 0.01, "start_y": -0.008, "start_z": -0.05, "start_roll": 0.02, "start_yaw": -0.03}
    outcome = KINDS["approach"].run(start, {}, 1)
    assert outcome.success, outcome.failure
    assert outcome.figures["final_position_error"] < 1e-3


def test_a_diagnosis_case_has_the_type_it_was_given():
    """`effects` is the case type: none has no truth (success = no alarm), two names both effects."""
    run = KINDS["diagnosis"].run
    none = run({"effects": 0}, {"duration": 15.0}, 7)
    assert none.labels["case_type"] == "none" and none.figures["effects"] == 0
    assert none.success == (none.figures["false_alarm"] == 0.0)
    two = run({"effects": 2}, {"duration": 15.0}, 7)
    assert two.labels["case_type"] == "two" and len(two.labels["effect_names"].split(",")) == 2
    with pytest.raises(ValueError, match="0, 1 or 2"):
        run({"effects": 3}, {"duration": 15.0}, 7)


@pytest.mark.parametrize("model", ["pose", "point", "range", "plane"])
def test_every_measurement_model_study_trial_reaches_its_floor(model):
    """One synthetic study trial per measurement model: error / Cramer-Rao floor near 1."""
    outcome = KINDS["calibration_model"].run({}, {"model": model, "postures": 50}, 3)
    assert 0.5 < outcome.figures["error_to_floor"] < 1.5, outcome.figures
    assert outcome.success
