"""The camera-pose calibration routine (EKF paper, Sections 2-4) on a live arm.

The eye-in-hand camera looks at a checkerboard fixed in the cell from many postures; each image
gives board_T_camera by PnP. Model, as for the FR3 data:

    board_T_camera(q) = board_T_base * chain(q, D-H errors) * tool_T_camera

with both end frames unknown (6 parameters each) beside the arm's identifiable D-H errors.
The routine needs from the outside only

    move_to(q) -> q_measured      jerk-limited move, settle, resolver angles (rad)
    grab() -> image | None        a frame exposed after the arm settled (None: no frame)

Postures come from viewpoints around the board (distance, tilt, roll spread) solved by IK on
the nominal model, seeded from the IK solution that looks straight at the board nearest the
start (so an arm starting at home works), and kept when the whole board is predicted inside
the image; the O3-optimal m of them are visited in nearest-neighbour order. Views where the
board is not found are skipped and counted, never guessed; if none of the first few shows it,
the run stops.

`camera_calibration_section` / `write_camera_calibrated_arm` give the arm file's
[calibration] table (D-H corrections; the frames are the cell's and the mount's, kept as
comments), `score_against_truth` scores a run against a simulator's true geometry.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable, Optional

import numpy as np
from numpy.typing import NDArray

from spacearm.base.config.board import DEFAULT_BOARD, BoardConfig, load_board
from spacearm.controller.calibration.board import BoardNotFound, board_pose
from spacearm.controller.calibration.errormodel import ErrorModel
from spacearm.controller.calibration.fr3 import camera_covariances
from spacearm.controller.calibration.identifiability import find_identifiable, identifiability_jacobian
from spacearm.controller.calibration.laser_routine import CalibrationRunError, nearest_neighbour_order, write_calibrated_arm
from spacearm.controller.calibration.observability import configuration_blocks, select_configurations
from spacearm.controller.calibration.residuals import Problem
from spacearm.controller.calibration.solvers import CalibrationResult, lm
from spacearm.controller.calibration.validation import compare_poses
from spacearm.base.config.arm import Calibration, load_arm_config
from spacearm.base.kinematics.forward import fk_batch
from spacearm.base.kinematics.inverse import solve_ik
from spacearm.base.kinematics.model import KinematicData, KinematicModel
from spacearm.base.spatial import inv_transform

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


def board_centre(st: CameraSetup) -> Array:
    nx, ny = st.board.inner
    centre_board = np.array([(nx - 1) * st.board.square / 2, (ny - 1) * st.board.square / 2, 0.0, 1.0])
    return (st.base_T_board @ centre_board)[:3]


def overhead_view(st: CameraSetup, q_start: Array, rng: np.random.Generator, distance: float = 0.42,
                  tries: int = 30) -> Array:
    """A posture looking straight at the board centre, the IK solution nearest q_start: the
    candidates are drawn around it, so they form one IK branch even if the arm starts far
    from the board (e.g. at home)."""
    data = KinematicData(st.kin)
    centre = board_centre(st)
    base_T_camera = look_at(centre - distance * st.base_T_board[:3, 2], centre, 0.0)
    base_T_tool = base_T_camera @ inv_transform(st.tool_T_camera)
    seeds = [np.asarray(q_start, float)] + list(st.kin.random_configurations(tries, rng, margin=0.2))
    best, best_travel = None, np.inf
    for seed in seeds:
        res = solve_ik(st.kin, data, base_T_tool, seed)
        if res.success and st.kin.within_limits(res.q):
            travel = float(np.max(np.abs(res.q - q_start)))
            if travel < best_travel:
                best, best_travel = res.q.copy(), travel
    if best is None:
        raise CalibrationRunError("no posture of the arm looks at the board; check the board pose and the mount")
    return best


def candidate_postures(st: CameraSetup, count: int, q_seed: Array, rng: np.random.Generator,
                       distance=(0.30, 0.55), max_tilt=np.radians(35.0), max_roll=np.radians(60.0),
                       max_tries: int = 4000) -> Array:
    """Joint postures (nominal IK) from which the whole board is predicted in view."""
    data = KinematicData(st.kin)
    centre = board_centre(st)
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
    residual: tuple[float, float]            # identification RMS position (m) / rotation (rad)
    seconds: float
    log: list[str] = field(default_factory=list)


def _rms(T_meas: Array, T_pred: Array) -> tuple[float, float]:
    s = compare_poses(T_meas, T_pred)
    return float(np.sqrt(np.mean(np.sum(s.pos ** 2, 1)))), float(np.sqrt(np.mean(np.sum(s.rot ** 2, 1))))


def identifiable_frames_first(em: ErrorModel, Q: Array, measured: Array, frames: list[str],
                              dh: list[str]) -> list[str]:
    """The identifiable set with ties resolved in favour of the end frames. A D-H error that
    an end frame can express as well (joint 1 about or along the base z, the last link's
    terms) cannot be told apart from a board or mount offset; kept as D-H, it would carry
    the board's placement error into the arm file, so the frame keeps it instead. Rank as
    find_identifiable's; order frames first, then D-H in the usual order."""
    probe = Problem(em, "pose", Q, measured, frames + dh)
    rank = len(find_identifiable(probe, frames + dh, Q=Q).kept)
    A = identifiability_jacobian(probe, frames + dh, Q=Q)
    A = A / np.maximum(np.linalg.norm(A, axis=0), 1e-300)
    basis: list[Array] = []
    kept: list[str] = []
    for j, name in enumerate(frames + dh):
        v = A[:, j].copy()
        for _ in range(2):                      # twice for numerical orthogonality
            for b in basis:
                v -= (b @ v) * b
        if np.linalg.norm(v) > 1e-3 and len(kept) < rank:
            basis.append(v / np.linalg.norm(v))
            kept.append(name)
    return kept


def identify(em: ErrorModel, Q: Array, measured: Array, prior_angle: float = np.radians(0.5),
             prior_length: float = 5e-3) -> tuple[CalibrationResult, CalibrationResult]:
    """Registration (frames only), then frames + identifiable D-H with a weak prior (MAP), each
    re-weighted by per-view covariances estimated from its residuals (as for the FR3 data)."""
    frames = em.frame_names("world") + em.frame_names("tool")
    reg = lm(Problem(em, "pose", Q, measured, frames, sigma=np.array([1e-3] * 3 + [3e-3] * 3)))
    for _ in range(2):
        reg = lm(Problem(em, "pose", Q, measured, frames, cov=camera_covariances(reg, em, Q), x0=reg.x))
    kept = identifiable_frames_first(em, Q, measured, frames, em.dh_names(with_beta=False))
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
                           progress: Callable[[str, int, int], None] | None = None,
                           give_up_after: int = 5) -> CameraRunResult:
    """Plan, visit, measure and identify. If none of the first `give_up_after` views shows the
    board, stop: the board or the camera is missing, and touring the rest would only waste
    arm time."""
    t0 = time.monotonic()
    rng = np.random.default_rng(seed)
    em = st.error_model()
    cands = candidate_postures(st, n_candidates + n_validation, overhead_view(st, q_start, rng), rng)
    validation, cands = cands[:n_validation], cands[n_validation:]
    kept = identifiable_frames_first(em, cands, em.poses(em.nominal, cands),
                                     em.frame_names("world") + em.frame_names("tool"), em.dh_names(with_beta=False))
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
            if skipped == step >= give_up_after:
                raise CalibrationRunError(f"checkerboard not seen in the first {step} views (last: {exc}); "
                                          "is the board in the cell and the camera streaming?") from None
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
    residual = _rms(meas, em.poses(full.x[: em.n_params], Q))
    return CameraRunResult(Q, meas, Qv, measv, skipped, full, reg, errors, frames, before, after, residual,
                           time.monotonic() - t0, log)


@dataclass(frozen=True)
class TruthScores:
    """The run scored against the simulator's true geometry (simulation only): board_T_camera
    error on fresh postures that see the board, and the absolute base-frame tool position
    error, over random poses, of the arm file `--apply` writes (nominal + identified D-H; the
    frames stay nominal)."""
    board_T_camera_before: tuple[float, float]   # RMS position (m) / rotation (rad), nominal
    board_T_camera_after: tuple[float, float]    # the same, identified model (D-H + frames)
    tool_position_before: float                  # mean |error| m, nominal arm
    tool_position_after: float                   # the same, nominal + identified D-H
    postures: int


def score_against_truth(st: CameraSetup, result: CameraRunResult, true_kin: KinematicModel,
                        true_base_T_board: Array, true_tool_T_camera: Array, q_seed: Array,
                        n: int = 50, seed: int = 7) -> TruthScores:
    em = st.error_model()
    rng = np.random.default_rng(seed)
    views = candidate_postures(st, n, overhead_view(st, q_seed, rng), rng)
    board_T_camera = inv_transform(true_base_T_board) @ fk_batch(true_kin, views) @ true_tool_T_camera
    x = result.fit.x[: em.n_params]
    corrections = {f"d{kind}": [result.errors.get(f"{kind}_{i + 1}", 0.0) for i in range(st.kin.nq)]
                   for kind in ("theta", "alpha", "a", "d")}
    calibrated = st.kin.with_errors(**corrections)
    Q = st.kin.random_configurations(n, rng, margin=0.1)
    p_true = fk_batch(true_kin, Q)[:, :3, 3]

    def mean_error(model: KinematicModel) -> float:
        return float(np.mean(np.linalg.norm(fk_batch(model, Q)[:, :3, 3] - p_true, axis=1)))

    return TruthScores(_rms(board_T_camera, em.poses(em.nominal, views)), _rms(board_T_camera, em.poses(x, views)),
                       mean_error(st.kin), mean_error(calibrated), n)


def setup_from_files(arm: str | Path, board: str | Path = DEFAULT_BOARD,
                     mount: str | Path | None = None, camera: str | Path | None = None) -> CameraSetup:
    """The routine's setup from the controller's own files (nominal values only)."""
    from spacearm.base.vision.camera import CameraModel
    from spacearm.base.vision.config import load_camera, load_mount
    kin = KinematicModel.from_config(load_arm_config(arm))
    board_config = load_board(board)
    cam = CameraModel.from_config(load_camera(camera) if camera else load_camera())
    end_T_camera = (load_mount(mount) if mount else load_mount()).end_T_camera.matrix()
    return CameraSetup(kin, board_config.pose.matrix(), end_T_camera, board_config, cam.K, cam.dist,
                       (cam.width, cam.height))


def camera_calibration_section(result: CameraRunResult, data: str = "") -> Calibration:
    """The arm file's [calibration] table: the D-H corrections only. The board and camera frame
    corrections describe the cell and the mount, not the arm (they go into comments)."""
    n = len(result.Q[0])

    def per_joint(kind: str) -> list[float]:
        return [result.errors.get(f"{kind}_{i + 1}", 0.0) for i in range(n)]

    return Calibration(
        method=f"camera pose (checkerboard corners + PnP), D-H + board and camera frames, {result.fit.method} "
               "with covariance weighting and a D-H prior (MAP)",
        date=datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"), data=data,
        configurations=len(result.Q), residual_rms=result.residual[0],
        validation_rms_before=result.validation_before[0] if len(result.Q_validation) else None,
        validation_rms_after=result.validation_after[0] if len(result.Q_validation) else None,
        dtheta=per_joint("theta"), dalpha=per_joint("alpha"), da=per_joint("a"), dd=per_joint("d"))


def write_camera_calibrated_arm(nominal_arm: str | Path, calibration: Calibration, result: CameraRunResult,
                                out: str | Path) -> None:
    """The nominal arm file plus [calibration] (as the laser routine writes it), the orientation
    residuals and the frame corrections as comments for provenance."""
    (_, rb), (_, ra) = result.validation_before, result.validation_after
    notes = [f"camera calibration: {len(result.Q)} views ({result.skipped} skipped), identification rotation "
             f"residual RMS {result.residual[1]:.6f} rad; held-out rotation RMS {rb:.6f} -> {ra:.6f} rad",
             "identified board and camera frame corrections (m, rad), not used by the controller:"]
    notes += [f"  {name} = {value!r}" for name, value in sorted(result.frames.items())]
    write_calibrated_arm(Path(nominal_arm), calibration, Path(out), "calibrate camera", notes)
