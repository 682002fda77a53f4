"""The lens model of a checkerboard pose estimate (LensModel), against OpenCV's own PnP: views of
the FR3 board at the real FR3 postures, imaged through a lens whose focal lengths, principal point
and radial distortion differ from the stated ones, then solved by cv2.solvePnP with the stated
(ideal) camera. The first-order model must reproduce that solver's bias, recover the lens errors
and predict held-out views at the noise level; the rigid and board-pitch models cannot."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from spacearm.controller.calibration import fr3 as F
from spacearm.controller.calibration.composite import Block, CompositeProblem
from spacearm.controller.calibration.lens_model import LensModel, pnp_bias

pytestmark = pytest.mark.skipif(not F.DATA.exists(), reason="FR3 data not available")
LENS = ("fx", "fy", "cx", "cy", "k1")
TRUE = np.array([-0.004, -0.002, -0.004, -0.001, -0.015])     # the size the real data's fits estimate
NOISE = 1e-4


def _solved(T: np.ndarray, lens: np.ndarray) -> np.ndarray:
    """board_T_cam as cv2.solvePnP finds it with an ideal camera from the corners' images through
    a lens off by `lens` (LENS order; normalised image units)."""
    fx, fy, cx, cy, k1 = lens
    out = T.copy()
    for n, M in enumerate(T):
        C = np.linalg.inv(M)
        X = F.FR3_BOARD @ C[:3, :3].T + C[:3, 3]
        u, v = X[:, 0] / X[:, 2], X[:, 1] / X[:, 2]
        seen = (np.abs(u) < F.D405_HALF_FOV[0]) & (np.abs(v) < F.D405_HALF_FOV[1])
        r2 = u ** 2 + v ** 2
        img = np.stack([u * (1 + fx + k1 * r2) + cx, v * (1 + fy + k1 * r2) + cy], 1)[seen]
        rvec, tvec = cv2.Rodrigues(C[:3, :3])[0], C[:3, 3].reshape(3, 1).copy()
        ok, rvec, tvec = cv2.solvePnP(F.FR3_BOARD[seen], img, np.eye(3), None, rvec, tvec, True,
                                      cv2.SOLVEPNP_ITERATIVE)
        assert ok
        Ce = np.eye(4)
        Ce[:3, :3], Ce[:3, 3] = cv2.Rodrigues(rvec)[0], tvec.ravel()
        out[n] = np.linalg.inv(Ce)
    return out


def _lens_views(data, em, lens, seed):
    seen = _solved(em.poses(em.nominal, data.Q), lens)
    seen[:, :3, 3] += np.random.default_rng(seed).normal(0.0, NOISE, (len(seen), 3))
    return F.FR3Data(data.Q, seen, data.base_T_flange)


def test_first_order_bias_matches_opencv_pnp(fr3_setup):
    """The model's shift of each view against OpenCV's solution: within 5 % of the bias (the
    views at the image's edge move by millimetres)."""
    data, em = fr3_setup
    T = em.poses(em.nominal, data.Q)
    solved = _solved(T, TRUE)
    B, count = pnp_bias(T, F.FR3_BOARD, F.D405_HALF_FOV, LENS)
    assert count.min() >= 100
    want = solved[:, :3, 3] - T[:, :3, 3]
    got = (B @ TRUE)[:, :3]
    assert np.abs(want).max() > 2e-3
    assert np.sqrt(np.mean((got - want) ** 2)) < 0.05 * np.sqrt(np.mean(want ** 2))


def test_lens_jacobian_matches_finite_differences(fr3_setup):
    data, em = fr3_setup
    model = LensModel(corners=F.FR3_BOARD, half_fov=F.D405_HALF_FOV, lens=LENS + ("k2",))
    e = np.concatenate([[0.003, -0.002], TRUE, [0.01]])
    pr = CompositeProblem(em, [Block(model, data.Q[:8], model.predict(em.poses(em.nominal, data.Q[:8]), e), 1e-3)], [])
    x = pr.nominal()
    x[-len(e):] = 0.8 * e
    r, A = pr.residual_and_jacobian(x)
    h = 1e-7
    for j in range(len(x) - len(e), len(x)):
        dx = np.zeros(len(x))
        dx[j] = h
        num = -(pr.residual_and_jacobian(x + dx)[0][:, 0] - pr.residual_and_jacobian(x - dx)[0][:, 0]) / (2 * h)
        got, want = A[:, 0, j].reshape(-1, 6)[:, :3], num.reshape(-1, 6)[:, :3]
        np.testing.assert_allclose(got, want, atol=1e-6 * np.abs(want).max())


def test_lens_errors_are_found_and_the_other_models_cannot_take_them(fr3_setup):
    data, em = fr3_setup
    views = _lens_views(data, em, TRUE, 8)
    perm = np.random.default_rng(2).permutation(len(data.Q))
    train, test = perm[:80], perm[80:]
    rigid = F.fit_split(views, train, test)
    board = F.fit_split(views, train, test, board_scale=True)
    lens = F.fit_split(views, train, test, lens=LENS)
    np.testing.assert_allclose([lens.full.estimate[f"camera_{t}"] for t in LENS], TRUE, atol=1.5e-3)
    assert lens.held_pos_rms["full"] < 3 * NOISE
    assert rigid.held_pos_rms["full"] > 3 * lens.held_pos_rms["full"]
    assert board.held_pos_rms["full"] > 3 * lens.held_pos_rms["full"]


def test_training_views_choose_the_lens_only_when_the_views_carry_it(fr3_setup):
    data, em = fr3_setup
    perm = np.random.default_rng(3).permutation(len(data.Q))
    chain = ("rigid", "board", "lens")
    assert F.fit_split_chosen(_lens_views(data, em, TRUE, 4), perm[:80], perm[80:], chain).camera == "lens"
    exact = F.fit_split_chosen(_lens_views(data, em, np.zeros(5), 5), perm[:80], perm[80:], chain)
    assert exact.camera == "rigid"
    assert exact.held_pos_rms["full"] < 3 * NOISE


def test_unknown_lens_term_is_refused_in_one_line():
    with pytest.raises(ValueError, match="unknown lens terms"):
        LensModel(lens=("k3",))
