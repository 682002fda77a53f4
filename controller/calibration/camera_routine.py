"""The camera-pose calibration routine (EKF paper, Sections 2-4) on a live arm.

The eye-in-hand camera looks at a checkerboard fixed in the cell from many postures; each image
gives board_T_camera by PnP. Model, as for the FR3 data:

    board_T_camera(q) = board_T_base * chain(q, D-H errors) * tool_T_camera

with both end frames unknown (6 parameters each) beside the arm's identifiable D-H errors.
The routine needs from the outside only

    move_to(q) -> q_measured      jerk-limited move, settle, resolver angles (rad)
    grab() -> image | None        a frame exposed after the arm settled (None: no frame)

Postures come from viewpoints around the board (distance, tilt, roll spread) solved by IK on
the nominal model and kept when the whole board is predicted inside the image; the O3-optimal
m of them are visited in nearest-neighbour order. Views where the board is not found are
skipped and counted, never guessed.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np
from numpy.typing import NDArray

from controller.calibration.board import BoardConfig, BoardNotFound, board_pose
from controller.calibration.errormodel import ErrorModel
from controller.calibration.fr3 import camera_covariances
from controller.calibration.identifiability import find_identifiable
from controller.calibration.laser_routine import CalibrationRunError, nearest_neighbour_order
from controller.calibration.observability import configuration_blocks, select_configurations
from controller.calibration.residuals import Problem
from controller.calibration.solvers import CalibrationResult, lm
from controller.calibration.validation import compare_poses
from controller.kinematics.inverse import solve_ik
from controller.kinematics.model import KinematicData, KinematicModel
from controller.kinematics.transforms import inv_transform

Array = NDArray[np.float64]


@dataclass(frozen=True)
class CameraSetup:
    kin: KinematicModel             # the controller's (nominal) arm
    base_T_board: Array             # nominal board placement (configs/calibration/board.toml)
    tool_T_camera: Array            # nominal camera mount (configs/vision/mount.toml)
    board: BoardConfig
    K: Array
    dist: Array
    image_size: tuple[int, int]     # width, height, px

    def error_model(self) -> ErrorModel:
        return ErrorModel.from_kinematics(self.kin, world=inv_transform(self.base_T_board),
                                          tool=self.tool_T_camera, world_prefix="board", tool_prefix="cam")

    def board_fully_visible(self, camera_T_board: Array, margin_px: float = 40.0) -> bool:
        import cv2
        corners = self.board.object_points()
        nx, ny = self.board.inner
        s = self.board.square
        outline = np.array([[-s, -s, 0], [nx * s, -s, 0], [nx * s, ny * s, 0], [-s, ny * s, 0]], float)
        pts = np.vstack([corners, outline])
        cam = pts @ camera_T_board[:3, :3].T + camera_T_board[:3, 3]
        if np.any(cam[:, 2] < 0.1):
            return False
        px, _ = cv2.projectPoints(pts, cv2.Rodrigues(camera_T_board[:3, :3])[0], camera_T_board[:3, 3],
                                  self.K, self.dist)
        px = px.reshape(-1, 2)
        w, h = self.image_size
        return bool(np.all((px > margin_px) & (px < np.array([w, h]) - margin_px)))


def look_at(eye: Array, target: Array, roll: float) -> Array:
    """base_T_camera with the optical axis (z) from `eye` to `target`, rolled about it."""
    z = target - eye
    z = z / np.linalg.norm(z)
    helper = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = np.cos(roll), np.sin(roll)
    x, y = c * x + s * y, -s * x + c * y
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, y, z])
    T[:3, 3] = eye
    return T


def candidate_postures(st: CameraSetup, count: int, q_seed: Array, rng: np.random.Generator,
                       distance=(0.30, 0.55), max_tilt=np.radians(35.0), max_roll=np.radians(60.0),
                       max_tries: int = 4000) -> Array:
    """Joint postures (nominal IK) from which the whole board is predicted in view."""
    data = KinematicData(st.kin)
    nx, ny = st.board.inner
    centre_board = np.array([(nx - 1) * st.board.square / 2, (ny - 1) * st.board.square / 2, 0.0, 1.0])
    centre = (st.base_T_board @ centre_board)[:3]
    normal = -st.base_T_board[:3, 2]          # board z points into the board: view from -z
    camera_T_tool = inv_transform(st.tool_T_camera)
    out: list[Array] = []
    for _ in range(max_tries):
        if len(out) >= count:
            break
        tilt, azimuth = rng.uniform(0, max_tilt), rng.uniform(-np.pi, np.pi)
        a = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
        a /= np.linalg.norm(a)
        b = np.cross(normal, a)
        direction = np.cos(tilt) * normal + np.sin(tilt) * (np.cos(azimuth) * a + np.sin(azimuth) * b)
        eye = centre + rng.uniform(*distance) * direction
        base_T_camera = look_at(eye, centre, rng.uniform(-max_roll, max_roll))
        base_T_tool = base_T_camera @ camera_T_tool
        res = solve_ik(st.kin, data, base_T_tool, q_seed)
        if not res.success or not st.kin.within_limits(res.q):
            continue
        if np.max(np.abs(res.q - q_seed)) > 1.5:   # stay in the seed's IK branch and keep moves short
            continue
        if st.board_fully_visible(inv_transform(base_T_camera) @ st.base_T_board):
            out.append(res.q.copy())
    if len(out) < count:
        raise CalibrationRunError(f"only {len(out)} of {count} postures see the whole board; "
                                  "check the board pose and the camera mount")
    return np.array(out)


@dataclass
class CameraRunResult:
    Q: Array
    board_T_camera: Array            # measured (N, 4, 4)
    Q_validation: Array
    board_T_camera_validation: Array
    skipped: int
    fit: CalibrationResult
    registration: CalibrationResult
    errors: dict[str, float]         # identified D-H corrections by name (m / rad)
    frames: dict[str, float]         # board_* and cam_* corrections
    validation_before: tuple[float, float]   # held-out RMS position (m) / rotation (rad), nominal
    validation_after: tuple[float, float]    # the same, calibrated
    seconds: float
    log: list[str] = field(default_factory=list)


def _rms(T_meas: Array, T_pred: Array) -> tuple[float, float]:
    s = compare_poses(T_meas, T_pred)
    return float(np.sqrt(np.mean(np.sum(s.pos ** 2, 1)))), float(np.sqrt(np.mean(np.sum(s.rot ** 2, 1))))


def identify(em: ErrorModel, Q: Array, measured: Array, prior_angle: float = np.radians(0.5),
             prior_length: float = 5e-3) -> tuple[CalibrationResult, CalibrationResult]:
    """Registration (frames only), then frames + identifiable D-H with a weak prior (MAP), each
    re-weighted by per-view covariances estimated from its residuals (as for the FR3 data)."""
    frames = em.frame_names("world") + em.frame_names("tool")
    reg = lm(Problem(em, "pose", Q, measured, frames, sigma=np.array([1e-3] * 3 + [3e-3] * 3)))
    for _ in range(2):
        reg = lm(Problem(em, "pose", Q, measured, frames, cov=camera_covariances(reg, em, Q), x0=reg.x))
    candidates = em.dh_names(with_beta=False) + frames
    kept = find_identifiable(Problem(em, "pose", Q, measured, candidates), candidates, Q=Q).kept
    prior = np.array([np.inf if n in frames else (prior_length if n.split("_")[0] in ("a", "d") else prior_angle)
                      for n in kept])
    full = reg
    for _ in range(3):
        full = lm(Problem(em, "pose", Q, measured, kept, cov=camera_covariances(full, em, Q), x0=full.x),
                  x_prior=em.nominal, sigma_prior=prior)
    return reg, full


def run_camera_calibration(st: CameraSetup, move_to: Callable[[Array], Array],
                           grab: Callable[[], Optional[np.ndarray]], q_start: Array, *, m: int = 40,
                           n_candidates: int = 120, n_validation: int = 15, seed: int = 0,
                           progress: Callable[[str, int, int], None] | None = None) -> CameraRunResult:
    t0 = time.monotonic()
    rng = np.random.default_rng(seed)
    em = st.error_model()
    cands = candidate_postures(st, n_candidates + n_validation, q_start, rng)
    validation, cands = cands[:n_validation], cands[n_validation:]
    candidates_all = em.dh_names(with_beta=False) + em.frame_names("world") + em.frame_names("tool")
    probe = Problem(em, "pose", cands, em.poses(em.nominal, cands), candidates_all)
    kept = find_identifiable(probe, candidates_all, Q=cands).kept
    blocks = configuration_blocks(Problem(em, "pose", cands, em.poses(em.nominal, cands), kept), cands)
    chosen = cands[select_configurations(blocks, m, "O3").indices]
    postures = np.vstack([chosen, validation])
    is_validation = np.r_[np.zeros(len(chosen), bool), np.ones(len(validation), bool)]
    Q, meas, Qv, measv, log, skipped = [], [], [], [], [], 0
    order = nearest_neighbour_order(postures, q_start)
    for step, k in enumerate(order, 1):
        q = move_to(postures[k])
        image = grab()
        if progress is not None:
            progress("validation" if is_validation[k] else "identification", step, len(order))
        predicted = inv_transform(em.poses(em.nominal, q[None])[0])   # camera_T_board, nominal
        try:
            if image is None:
                raise BoardNotFound("no camera frame")
            view = board_pose(image, st.board, st.K, st.dist, predicted=predicted)
        except BoardNotFound as exc:
            skipped += 1
            log.append(f"posture {step}: {exc}; skipped")
            continue
        (Qv if is_validation[k] else Q).append(q)
        (measv if is_validation[k] else meas).append(inv_transform(view.camera_T_board))
    if len(Q) < max(10, len(kept) // 6 + 3):
        raise CalibrationRunError(f"only {len(Q)} usable views ({skipped} skipped) for {len(kept)} parameters")
    Q, meas, Qv, measv = np.array(Q), np.array(meas), np.array(Qv), np.array(measv)
    reg, full = identify(em, Q, meas)
    before = after = (float("nan"), float("nan"))
    if len(Qv):
        before = _rms(measv, em.poses(em.nominal, Qv))
        after = _rms(measv, em.poses(full.x[: em.n_params], Qv))
    delta = {name: float(full.x[i] - em.nominal[i]) for i, name in enumerate(em.names) if name in full.free}
    frames = {n: v for n, v in delta.items() if n.startswith(("board_", "cam_"))}
    errors = {n: v for n, v in delta.items() if n not in frames}
    return CameraRunResult(Q, meas, Qv, measv, skipped, full, reg, errors, frames, before, after,
                           time.monotonic() - t0, log)
