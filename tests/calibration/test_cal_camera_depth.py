"""Terms of the camera's own pose estimate of its target, checked against finite differences and
against views rendered with a known error at the real FR3 postures:
- the depth scale (CameraPoseModel): a focal length off by a fraction s places the target (1 + s)
  times as deep along the optical axis (the rigid arm + frames model cannot take that error);
- the board's pitch per axis (BoardScaleModel): a target whose squares are off by (s_x, s_y) along
  its own axes places the camera at (x (1 + s_x), y (1 + s_y), z) in the target frame; the per-split
  choice (fit_split_chosen, the training views' leave-one-out only) must take the term when the
  views carry it and leave it out when they do not."""
from __future__ import annotations

import numpy as np
import pytest

from spacearm.controller.calibration import fr3 as F
from spacearm.controller.calibration.composite import Block, CompositeProblem
from spacearm.controller.calibration.measurement_models import BoardScaleModel, CameraPoseModel

pytestmark = pytest.mark.skipif(not F.DATA.exists(), reason="FR3 data not available")
TRUE_SCALE = 0.008           # a focal length 0.8 % off
TRUE_PITCH = np.array([-0.008, -0.005])      # a board printed 0.8 % / 0.5 % small along x / y


@pytest.mark.parametrize("model, e", [(CameraPoseModel(), [0.02]), (BoardScaleModel(), [0.012, -0.018])])
def test_camera_term_jacobian_matches_finite_differences(fr3_setup, model, e):
    data, em = fr3_setup
    rng = np.random.default_rng(4)
    seen = model.predict(em.poses(em.nominal, data.Q[:6]), 0.75 * np.array(e))   # near the prediction,
    pr = CompositeProblem(em, [Block(model, data.Q[:6], seen, 1e-3)], [])         # as at a solution
    x = pr.nominal() + rng.normal(0, 1e-3, len(pr.names))
    x[-len(e):] = e
    r, A = pr.residual_and_jacobian(x)
    h = 1e-7
    for j in [0, 4, 9, 20] + list(range(len(x) - len(e) - 1, len(x))):
        dx = np.zeros(len(x))
        dx[j] = h
        num = -(pr.residual_and_jacobian(x + dx)[0][:, 0] - pr.residual_and_jacobian(x - dx)[0][:, 0]) / (2 * h)
        # Position rows (the rotation rows are PoseModel's, first order in the residual as there).
        got, want = A[:, 0, j].reshape(-1, 6)[:, :3], num.reshape(-1, 6)[:, :3]
        np.testing.assert_allclose(got, want, atol=1e-8 * max(np.abs(want).max(), 1.0))


def test_predicted_depth_is_scaled_along_the_optical_axis(fr3_setup):
    data, em = fr3_setup
    T = em.poses(em.nominal, data.Q[:5])
    seen = CameraPoseModel().predict(T, np.array([TRUE_SCALE]))
    depth = lambda M: np.linalg.inv(M)[:, 2, 3]          # the target's depth in the camera  # noqa: E731
    lateral = lambda M: np.linalg.inv(M)[:, :2, 3]       # noqa: E731
    np.testing.assert_allclose(depth(seen), (1 + TRUE_SCALE) * depth(T), rtol=1e-12)
    np.testing.assert_allclose(lateral(seen), lateral(T), atol=1e-12)
    np.testing.assert_allclose(seen[:, :3, :3], T[:, :3, :3])


def test_a_focal_length_error_is_found_and_the_rigid_model_cannot_take_it(fr3_setup):
    data, em = fr3_setup
    rng = np.random.default_rng(8)
    seen = CameraPoseModel().predict(em.poses(em.nominal, data.Q), np.array([TRUE_SCALE]))
    seen[:, :3, 3] += rng.normal(0.0, 1e-4, (len(seen), 3))
    views = F.FR3Data(data.Q, seen, data.base_T_flange)
    perm = np.random.default_rng(2).permutation(len(data.Q))
    rigid = F.fit_split(views, perm[:80], perm[80:])
    camera = F.fit_split(views, perm[:80], perm[80:], depth_scale=True)
    assert camera.full.estimate["camera_depth_scale"] == pytest.approx(TRUE_SCALE, abs=5e-4)
    assert camera.held_pos_rms["full"] < 0.5e-3
    assert rigid.held_pos_rms["full"] > 2 * camera.held_pos_rms["full"]


def test_board_pitch_scales_the_position_along_the_board_axes_only(fr3_setup):
    data, em = fr3_setup
    T = em.poses(em.nominal, data.Q[:5])
    seen = BoardScaleModel().predict(T, TRUE_PITCH)
    np.testing.assert_allclose(seen[:, :2, 3], T[:, :2, 3] * (1 + TRUE_PITCH), rtol=1e-12)
    np.testing.assert_allclose(seen[:, 2, 3], T[:, 2, 3], atol=1e-15)
    np.testing.assert_allclose(seen[:, :3, :3], T[:, :3, :3])


def _pitched_views(data, em, pitch, seed):
    seen = BoardScaleModel().predict(em.poses(em.nominal, data.Q), pitch)
    seen[:, :3, 3] += np.random.default_rng(seed).normal(0.0, 1e-4, (len(seen), 3))
    return F.FR3Data(data.Q, seen, data.base_T_flange)


def test_training_views_choose_the_board_pitch_only_when_the_views_carry_it(fr3_setup):
    data, em = fr3_setup
    perm = np.random.default_rng(2).permutation(len(data.Q))
    pitched = F.fit_split_chosen(_pitched_views(data, em, TRUE_PITCH, 8), perm[:80], perm[80:])
    np.testing.assert_allclose([pitched.full.estimate.get(f"camera_scale_{a}", np.nan) for a in "xy"],
                               TRUE_PITCH, atol=1e-3)
    assert pitched.held_pos_rms["full"] < 0.5e-3
    exact = F.fit_split_chosen(_pitched_views(data, em, np.zeros(2), 9), perm[:80], perm[80:])
    assert "camera_scale_x" not in exact.full.free
    assert exact.held_pos_rms["full"] < 0.5e-3
