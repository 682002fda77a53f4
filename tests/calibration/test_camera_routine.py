"""Camera-pose calibration routine on rendered checkerboard images (no bus): the held-out
board_T_camera error of the identified model must drop well below the nominal one, and a view
without a board is skipped, not guessed."""
from __future__ import annotations

import numpy as np
import pytest

from controller.calibration.board import BoardNotFound, board_pose, load_board
from controller.calibration.camera_routine import CameraSetup, run_camera_calibration
from controller.config.arm import load_arm_config
from controller.kinematics.forward import fk
from controller.kinematics.model import KinematicData, KinematicModel
from controller.kinematics.transforms import inv_transform, xyz_rpy_to_transform
from controller.vision.camera import CameraModel
from controller.vision.config import load_camera, load_mount
from firmware_sim.calibration_board import render_board

ARM = load_arm_config("configs/arm/oru_testbed_6dof.toml")
RESOLVER = np.radians(25 / 3600)


@pytest.fixture(scope="module")
def cell():
    kin = KinematicModel.from_config(ARM)
    board = load_board()
    camera = CameraModel.from_config(load_camera())
    mount = load_mount().end_T_camera.matrix()
    return kin, board, camera, mount


def test_board_pose_from_a_rendered_image_is_accurate_and_failures_are_reported(cell):
    _, board, cam, _ = cell
    rng = np.random.default_rng(3)
    T = xyz_rpy_to_transform([-0.07, -0.05, 0.40], [0.2, -0.15, 0.3])
    image = render_board(T, board, cam.K, cam.dist, (cam.width, cam.height), rng)
    view = board_pose(image, board, cam.K, cam.dist, predicted=T)
    assert np.linalg.norm(view.camera_T_board[:3, 3] - T[:3, 3]) < 0.5e-3
    R = view.camera_T_board[:3, :3].T @ T[:3, :3]
    assert np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)) < np.radians(0.2)
    blank = np.full((cam.height, cam.width), 60, np.uint8)
    with pytest.raises(BoardNotFound):
        board_pose(blank, board, cam.K, cam.dist)


def test_camera_routine_cuts_held_out_pose_error(cell):
    kin, board, cam, mount = cell
    rng = np.random.default_rng(1)
    true = kin.with_errors(dtheta=rng.normal(0, 1e-3, 6), dalpha=rng.normal(0, 1e-3, 6),
                           da=rng.normal(0, 1e-3, 6), dd=rng.normal(0, 1e-3, 6))
    board_true = board.pose.matrix() @ board.true_offset.matrix()
    mount_true = mount @ xyz_rpy_to_transform([0.001, -0.002, 0.001], [0.002, 0.001, -0.003])
    data = KinematicData(true)
    state = {"q": np.array(ARM.postures["ready"]), "frames": 0}

    def move_to(q):
        state["q"] = np.asarray(q, float)
        return np.round(state["q"] / RESOLVER) * RESOLVER

    def grab():
        state["frames"] += 1
        if state["frames"] == 3:          # one dropped frame: must be skipped
            return None
        camera_T_base = inv_transform(fk(true, data, state["q"]) @ mount_true)
        return render_board(camera_T_base @ board_true, board, cam.K, cam.dist, (cam.width, cam.height), rng)

    setup = CameraSetup(kin, board.pose.matrix(), mount, board, cam.K, cam.dist, (cam.width, cam.height))
    result = run_camera_calibration(setup, move_to, grab, np.array(ARM.postures["ready"]), m=30,
                                    n_candidates=80, n_validation=10)
    assert result.skipped == 1 and "no camera frame" in result.log[0]
    assert result.fit.status == "converged"
    pos_before, rot_before = result.validation_before
    pos_after, rot_after = result.validation_after
    assert pos_after < 0.3 * pos_before and rot_after < 0.4 * rot_before
