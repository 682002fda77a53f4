"""Camera-pose calibration routine on rendered checkerboard images (no bus): the held-out
board_T_camera error of the identified model must drop well below the nominal one, a view
without a board is skipped, not guessed, a board never seen stops the run early, and the
simulator's camera shows the board at its true pose only when asked to."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from spacearm.console.commands.calibrate import _print_camera_result
from spacearm.base.config.board import load_board
from spacearm.controller.calibration.board import BoardNotFound, board_pose
from spacearm.controller.calibration.camera_routine import (CameraSetup, camera_calibration_section, candidate_postures,
                                                   overhead_view, run_camera_calibration, score_against_truth,
                                                   write_camera_calibrated_arm)
from spacearm.controller.calibration.laser_routine import CalibrationRunError
from spacearm.base.config.arm import load_arm_config
from spacearm.base.kinematics.forward import fk
from spacearm.base.kinematics.model import KinematicData, KinematicModel
from spacearm.base.spatial import inv_transform, xyz_rpy_to_transform
from spacearm.base.vision.camera import CameraModel
from spacearm.base.vision.config import load_camera, load_mount
from spacearm.base.vision.frames import LocalFrameSource
from spacearm.firmware_sim.calibration_board import render_board
from spacearm.firmware_sim.camera.service import CameraService

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


@pytest.fixture(scope="module")
def offline_run(cell):
    """The routine on a true arm with D-H, board and mount errors, images rendered offline."""
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
    return SimpleNamespace(setup=setup, result=result, true=true, board_true=board_true, mount_true=mount_true)


def test_camera_routine_cuts_held_out_pose_error(offline_run):
    result = offline_run.result
    assert result.skipped == 1 and "no camera frame" in result.log[0]
    assert result.fit.status == "converged"
    pos_before, rot_before = result.validation_before
    pos_after, rot_after = result.validation_after
    assert pos_after < 0.3 * pos_before and rot_after < 0.4 * rot_before
    run = offline_run
    scores = score_against_truth(run.setup, result, run.true, run.board_true, run.mount_true,
                                 np.array(ARM.postures["ready"]), n=20)
    assert scores.board_T_camera_after[0] < 0.3 * scores.board_T_camera_before[0]


def test_applied_arm_file_loads_with_provenance_and_the_console_reports_it(offline_run, tmp_path, capsys):
    result = offline_run.result
    out = tmp_path / "calibrated.toml"
    write_camera_calibrated_arm("configs/arm/oru_testbed_6dof.toml", camera_calibration_section(result, "views.csv"),
                                result, out)
    config = load_arm_config(out)
    assert config.calibration.configurations == len(result.Q) and "camera pose" in config.calibration.method
    assert config.calibration.validation_rms_after == pytest.approx(result.validation_after[0])
    assert "calibrate camera --apply" in out.read_text() and "#   cam_x = " in out.read_text()
    _print_camera_result(result, None, out, as_json=False)       # what `spacearm calibrate camera` prints
    text = capsys.readouterr().out
    assert "held-out board_T_camera RMS" in text and str(out) in text


def test_routine_stops_early_when_the_board_is_never_seen(cell):
    kin, board, cam, mount = cell
    moves = []
    blank = np.full((cam.height, cam.width), 60, np.uint8)
    setup = CameraSetup(kin, board.pose.matrix(), mount, board, cam.K, cam.dist, (cam.width, cam.height))
    with pytest.raises(CalibrationRunError, match="not seen in the first 5 views"):
        run_camera_calibration(setup, lambda q: moves.append(q) or q, lambda: blank, np.array(ARM.postures["home"]),
                               m=12, n_candidates=30, n_validation=3)
    assert len(moves) == 5


def test_simulated_camera_shows_the_board_at_its_true_pose_only_when_asked(cell):
    kin, board, cam, mount = cell
    setup = CameraSetup(kin, board.pose.matrix(), mount, board, cam.K, cam.dist, (cam.width, cam.height))
    rng = np.random.default_rng(0)
    # a tilted view: straight on, a small board's tilt is weakly observed by PnP (mrad)
    q = candidate_postures(setup, 1, overhead_view(setup, np.array(ARM.postures["home"]), rng), rng)[0]
    base_T_camera = fk(kin, KinematicData(kin), q) @ mount
    sink = LocalFrameSource()
    service = CameraService.from_files(None, sink)
    service.render_now(0.0, 1, base_T_camera)
    with pytest.raises(BoardNotFound):
        board_pose(sink.latest().image, board, cam.K, cam.dist)
    service.show_board(board)
    service.render_now(0.1, 2, base_T_camera)
    true_camera_T_board = inv_transform(base_T_camera) @ board.pose.matrix() @ board.true_offset.matrix()
    view = board_pose(sink.latest().image, board, cam.K, cam.dist, predicted=true_camera_T_board)
    assert np.linalg.norm(view.camera_T_board[:3, 3] - true_camera_T_board[:3, 3]) < 1e-3
    R = view.camera_T_board[:3, :3].T @ true_camera_T_board[:3, :3]
    assert np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1)) < np.radians(0.3)
    assert sink.latest().true_camera_T_marker is not None       # frames still carry the marker truth
