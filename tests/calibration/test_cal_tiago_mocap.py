"""Real TIAGo motion-capture data (../shared/data/tiago_mocap, FIGAROH's examples): one day fits,
the other day validates. The mocap frame's offset must be the registration's, not the arm's."""
from __future__ import annotations

import numpy as np
import pytest

from spacearm.controller.calibration.tiago_mocap import DATA, fit_tiago

pytestmark = pytest.mark.skipif(not DATA.exists(), reason="shared TIAGo data not present")


@pytest.fixture(scope="module")
def full():
    return fit_tiago()


def test_registration_is_estimated_not_absorbed_into_the_arm(full):
    rep = full.report
    assert {f"base_{k}" for k in ("x", "y", "z", "rx", "ry", "rz")} <= set(rep.result.free), rep.identifiability.summary()
    est = rep.result.estimate
    dh = {n: v for n, v in est.items() if n.split("_")[0] in ("theta", "alpha", "beta")}
    # The old fit put the mocap frame's offset into theta_2 (+17 deg); now every angle is a few
    # degrees at most (arm_5's zero, theta_6 here, is ~3 deg off: FIGAROH finds -2.8 deg too).
    assert max(abs(np.degrees(v)) for v in dh.values()) < 5.0, dh
    assert abs(np.degrees(est.get("theta_2", 0.0))) < 1.5
    assert rep.verdict.ok, rep.verdict.message()


def test_validation_day_improves_and_extrapolated_postures_are_flagged(full):
    reg = fit_tiago(registration_only=True)
    assert full.validation_rms < reg.validation_rms
    flagged = {h.index: h.outside for h in full.report.held_out if h.outside}
    # Rows 0 and 4 of 2021-11-26 move arm_6 and arm_7 beyond anything measured on 2021-11-30.
    assert {0, 4} <= set(flagged) and "arm_6_joint" in flagged[4]
    assert len(full.report.held_out) == 62


def test_kept_set_does_not_depend_on_the_tool_point_start(full):
    other = fit_tiago(tool_point=(0.1, 0.05, -0.03))
    assert other.report.result.free == full.report.result.free
    assert abs(other.validation_rms - full.validation_rms) < 1e-6


def test_validation_is_reported_per_axis_of_the_mocap_frame(full):
    # Per axis, read back from the per-posture residual vectors: the three axes' squares add up
    # to the pooled figure, and no axis is left out (all three carry error on real data).
    axes = full.report.held_axis_rms()
    assert axes.shape == (3,) and np.all(axes > 1e-4)
    assert np.sqrt(np.sum(axes ** 2)) == pytest.approx(full.validation_rms, rel=1e-9)
    worst = max(full.report.held_out, key=lambda h: h.after)
    assert np.linalg.norm(worst.residual) == pytest.approx(worst.after, rel=1e-9)


def test_d_h_groups_chosen_on_the_identification_day_validate_better_on_the_other(full):
    # Leave-one-posture-out on 2021-11-30 alone (37 postures, 31 terms) drops the a_i lengths; the
    # other day, never seen by the choice, is predicted better than by the full set (3.06 mm) and
    # than FIGAROH full_params on the same split (3.22 mm in bench/bench_calibration_real.py).
    from spacearm.controller.calibration.trusted_fit import FitOptions
    sel = fit_tiago(opts=FitOptions(select_groups=True))
    assert sel.report.selection.dropped == ("a",), sel.report.selection.summary()
    assert not any(n.startswith("a_") for n in sel.report.result.free) and sel.report.verdict.ok
    assert sel.validation_rms < full.validation_rms - 0.05e-3 and sel.validation_rms < 3.0e-3


def test_the_identification_postures_repeat_on_the_validation_day_better_than_the_fit_predicts(full):
    """Every identification posture was measured again on the other day; after the best rigid
    transform between the days' frames they agree to ~1 mm, while the fit leaves more than that on
    its own training postures: what is left is repeatable, a term the model does not have."""
    from spacearm.controller.calibration.tiago_mocap import day_to_day_repeatability
    rows, raw, rigid = day_to_day_repeatability()
    assert len(rows) == 37 and len(set(rows.tolist())) == 37
    assert rigid < raw < 2.0e-3
    assert rigid < 0.75 * full.train_rms


def test_training_loo_is_the_group_selections_criterion(full):
    """The bench sets the identification day's leave-one-out beside the other day's figure; it must be
    the number the group selection minimised, for the full set and for the selected one."""
    from spacearm.controller.calibration.tiago_mocap import training_loo
    from spacearm.controller.calibration.trusted_fit import FitOptions
    sel = fit_tiago(opts=FitOptions(select_groups=True))
    steps = sel.report.selection.steps
    assert training_loo(full) == pytest.approx(steps[0][1], rel=1e-9)
    assert training_loo(sel) == pytest.approx(steps[-1][1], rel=1e-9)
    assert training_loo(sel) < training_loo(full) and training_loo(full) > 2 * full.train_rms


def test_arm_6_compliance_chosen_on_the_identification_day_carries_to_the_other(full):
    # With the compliances among the candidates (each bounded as a deflection, each kept or dropped
    # by the same leave-one-out on 2021-11-30 alone), arm_6's drive (k_7) stays: it lowers that
    # day's leave-one-out by 30 % and the other day, never seen by the choice, validates below the
    # issue's 2.9 mm and below the rigid selection's 2.96 mm (FIGAROH full_params: 3.22 mm).
    from spacearm.controller.calibration.tiago_mocap import training_loo
    from spacearm.controller.calibration.trusted_fit import FitOptions
    rigid = fit_tiago(opts=FitOptions(select_groups=True))
    sel = fit_tiago(elastic=True, opts=FitOptions(select_groups=True))
    rep = sel.report
    assert "a" in rep.selection.dropped and "k_7" in rep.result.free, rep.selection.summary()
    assert 0.01 < rep.estimate["k_7"] < 0.06 and rep.estimate["k_7"] > 3 * rep.std["k_7"]
    assert rep.verdict.ok, rep.verdict.message()
    assert training_loo(sel) < 0.8 * training_loo(rigid)
    assert sel.validation_rms < rigid.validation_rms and sel.validation_rms <= 2.9e-3


def test_the_marker_plates_orientation_points_at_arm_6s_drive():
    # The identification day's plate orientation (unused by the marker-1 fits): what the rigid
    # model leaves, resolved onto the wrist, is arm_6's angle in step with its gravity torque, at
    # a slope of the size the marker-1 fit then estimates for k_7; arm_5 and arm_7 show no such thing.
    from spacearm.controller.calibration.tiago_plate import plate_check
    from spacearm.controller.calibration.trusted_fit import FitOptions
    c = plate_check(fit_tiago(opts=FitOptions(select_groups=True)))
    assert c.used + c.singular == 37 and c.used >= 30
    assert c.orientation_rms > 5e-3                     # the plate itself is good to ~1-2 mrad
    assert c.torque_correlation[1] > 0.5 and max(abs(c.torque_correlation[0]), abs(c.torque_correlation[2])) < 0.3
    assert 0.01 < c.torque_slope[1] < 0.05
