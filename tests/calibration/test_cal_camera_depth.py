"""The camera's depth scale (CameraPoseModel): a focal length off by a fraction s makes the
camera's own pose estimate place the target (1 + s) times as deep along the optical axis. Checked
against finite differences and against views rendered with a known scale at the real FR3 postures
(the rigid arm + frames model cannot take that error, the camera model must find s)."""
from __future__ import annotations

import numpy as np
import pytest

from spacearm.controller.calibration import fr3 as F
from spacearm.controller.calibration.composite import Block, CompositeProblem
from spacearm.controller.calibration.errormodel import ErrorModel
from spacearm.controller.calibration.measurement_models import CameraPoseModel

pytestmark = pytest.mark.skipif(not F.DATA.exists(), reason="FR3 data not available")
TRUE_SCALE = 0.008           # a focal length 0.8 % off


@pytest.fixture(scope="module")
def setup():
    data = F.load_fr3()
    kin = F.fr3_kinematics()
    W0, cam0 = F.initial_frames(kin, data, np.arange(len(data.Q)))
    em = ErrorModel.from_kinematics(kin, world=W0, tool=cam0, world_prefix="board", tool_prefix="cam")
    return data, em


def test_depth_scale_jacobian_matches_finite_differences(setup):
    data, em = setup
    rng = np.random.default_rng(4)
    seen = CameraPoseModel().predict(em.poses(em.nominal, data.Q[:6]), np.array([0.015]))   # near the prediction,
    pr = CompositeProblem(em, [Block(CameraPoseModel(), data.Q[:6], seen, 1e-3)], [])          # as at a solution
    x = pr.nominal() + rng.normal(0, 1e-3, len(pr.names))
    x[-1] = 0.02
    r, A = pr.residual_and_jacobian(x)
    h = 1e-7
    for j in [0, 4, 9, 20, len(x) - 2, len(x) - 1]:
        dx = np.zeros(len(x))
        dx[j] = h
        num = -(pr.residual_and_jacobian(x + dx)[0][:, 0] - pr.residual_and_jacobian(x - dx)[0][:, 0]) / (2 * h)
        # Position rows (the rotation rows are PoseModel's, first order in the residual as there).
        got, want = A[:, 0, j].reshape(-1, 6)[:, :3], num.reshape(-1, 6)[:, :3]
        np.testing.assert_allclose(got, want, atol=1e-8 * max(np.abs(want).max(), 1.0))


def test_predicted_depth_is_scaled_along_the_optical_axis(setup):
    data, em = setup
    T = em.poses(em.nominal, data.Q[:5])
    seen = CameraPoseModel().predict(T, np.array([TRUE_SCALE]))
    depth = lambda M: np.linalg.inv(M)[:, 2, 3]          # the target's depth in the camera  # noqa: E731
    lateral = lambda M: np.linalg.inv(M)[:, :2, 3]       # noqa: E731
    np.testing.assert_allclose(depth(seen), (1 + TRUE_SCALE) * depth(T), rtol=1e-12)
    np.testing.assert_allclose(lateral(seen), lateral(T), atol=1e-12)
    np.testing.assert_allclose(seen[:, :3, :3], T[:, :3, :3])


def test_a_focal_length_error_is_found_and_the_rigid_model_cannot_take_it(setup):
    data, em = setup
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
