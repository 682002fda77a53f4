"""Real eye-in-hand data of a Franka FR3 (../shared/data/fr3_eye_in_hand): fit and held-out error.

Measurement model: board_T_cam(q) = board_T_base * chain(q) * T_flange * flange_T_cam, with the
two unknown frames as parameter blocks "board_*" (world side) and "cam_*" (tool side), and the
arm's modified D-H errors. Two fits per random 80/34 split:
  registration  only the 12 frame parameters,
  full          frames + the identifiable D-H parameters (identifiability on the training set),
both weighted LM with noise levels re-estimated from the registration residuals, the full fit
with a weak prior on the D-H errors (MAP) so that 80 postures do not overfit. By default each
split's full fit is made with the camera models of CAMERA_CHAIN - rigid, the board's pitch per axis
(BoardScaleModel), the lens's bias of the pose estimate (LensModel: focal lengths, principal point,
radial distortion) - and keeps the richer one while it lowers the leave-one-view-out error on its
own training views by MIN_GAIN, so the held-out views take no part in the choice.
"""
from __future__ import annotations

import csv
import dataclasses
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from spacearm.base.paths import SHARED_DATA
from spacearm.controller.calibration.composite import Block, CompositeProblem
from spacearm.controller.calibration.datafile import DataFileError
from spacearm.controller.calibration.errormodel import ErrorModel
from spacearm.controller.calibration.identifiability import find_identifiable
from spacearm.controller.calibration.fit_checks import Priors
from spacearm.controller.calibration.lens_model import LensModel, board_corners
from spacearm.controller.calibration.measurement_models import BoardScaleModel, CameraPoseModel, PoseModel
from spacearm.controller.calibration.residuals import Problem
from spacearm.controller.calibration.solvers import CalibrationResult, lm
from spacearm.controller.calibration.trusted_fit import loo_position_rms
from spacearm.controller.calibration.validation import compare_poses
from spacearm.base.kinematics import KinematicModel
from spacearm.base.spatial import rotz, trans

Array = NDArray[np.float64]
DATA = SHARED_DATA / "fr3_eye_in_hand" / "samples.csv"

FR3_A = [0, 0, 0, 0.0825, -0.0825, 0, 0.088]
FR3_D = [0.333, 0, 0.316, 0, 0.384, 0, 0]
FR3_ALPHA = [0, -np.pi / 2, np.pi / 2, np.pi / 2, -np.pi / 2, np.pi / 2, np.pi / 2]
FR3_FLANGE = 0.107
FR3_Q_MIN = [-2.7437, -1.7837, -2.9007, -3.0421, -2.8065, 0.5445, -3.0159]
FR3_Q_MAX = [2.7437, 1.7837, 2.9007, -0.1518, 2.8065, 4.5169, 3.0159]
MIN_GAIN = 0.02      # a camera term must lower the training leave-one-out RMS by 2 % (as group_selection)
# The board and the camera, for the lens model: not in the data file. The source's example script
# (PhilNad/robot-arm-kinematic-calibration, Examples/FrankaReal.py) states a 0.5 m board of 25 mm
# squares with its origin at the pattern's corner: 17 x 17 inner corners, running along -x and +y
# of the board frame (the views aim at (-0.21, 0.23) m, the pattern's centre). The RealSense
# D405's field of view is 87 x 58 deg (Intel's datasheet); x is the image's long side.
FR3_BOARD = board_corners(0.025, 17, 17, sign=(-1.0, 1.0))
D405_HALF_FOV = (float(np.tan(np.radians(87.0 / 2))), float(np.tan(np.radians(58.0 / 2))))
# Nested camera models, each kept over the one before when it lowers the training leave-one-out
# by MIN_GAIN: rigid, the board's pitch, the lens (pinhole + first radial term), the second radial term.
CAMERA_CHAIN = ("rigid", "board", "lens", "lens_k2")
LENS = {"lens": ("fx", "fy", "cx", "cy", "k1"), "lens_k2": ("fx", "fy", "cx", "cy", "k1", "k2")}


def fr3_kinematics() -> KinematicModel:
    n = 7
    return KinematicModel(
        convention="modified", a=FR3_A, alpha=FR3_ALPHA, d=FR3_D, theta_offset=np.zeros(n),
        beta=np.zeros(n), beta_mask=np.zeros(n, bool), base=np.eye(4),
        tool=trans(0, 0, FR3_FLANGE), q_min=FR3_Q_MIN, q_max=FR3_Q_MAX, v_max=np.ones(n),
        a_max=np.ones(n), j_max=np.ones(n), q_home=np.zeros(n),
        joint_names=tuple(f"fr3_joint{i + 1}" for i in range(n)), name="fr3")


@dataclass
class FR3Data:
    Q: Array                 # (N, 7) rad
    board_T_cam: Array       # (N, 4, 4)
    base_T_flange: Array     # (N, 4, 4) controller FK (nominal)


def load_fr3(path: Path = DATA) -> FR3Data:
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"FR3 data not found: {path}")
    with path.open() as fh:
        rows = list(csv.DictReader(fh))

    def column(name: str) -> Array:
        try:
            values = np.array([float(r[name]) for r in rows])
        except KeyError:
            raise DataFileError(f"{path}: needs column {name} (q1..q7, board_T_cam_00..23, base_T_flange_00..23)") \
                from None
        except (TypeError, ValueError) as exc:
            raise DataFileError(f"{path}: column {name}: bad number ({exc})") from None
        if not np.all(np.isfinite(values)):
            raise DataFileError(f"{path}: column {name}: non-finite values (nan/inf)")
        return values

    def mats(prefix: str) -> Array:
        M = np.zeros((len(rows), 4, 4))
        for i in range(3):
            for j in range(4):
                M[:, i, j] = column(f"{prefix}_{i}{j}")
        M[:, 3, 3] = 1.0
        return M
    if len(rows) < 10:
        raise DataFileError(f"{path}: {len(rows)} samples, the FR3 study needs at least 10")
    Q = np.stack([column(f"q{i + 1}") for i in range(7)], axis=1)
    return FR3Data(Q, mats("board_T_cam"), mats("base_T_flange"))


def _orthonormal(R: Array) -> Array:
    U, _, Vt = np.linalg.svd(R)
    D = np.diag([1.0, 1.0, np.linalg.det(U @ Vt)])
    return U @ D @ Vt


def initial_frames(kin: KinematicModel, data: FR3Data, rows: Array) -> tuple[Array, Array]:
    """Starting flange_T_cam (README's rough numbers) and board_T_base (averaged per posture)."""
    cam = trans(0.0945, -0.009, 0.04055) @ rotz(np.pi / 2)
    em = ErrorModel.from_kinematics(kin, tool=cam)
    base_T_cam = em.poses(em.nominal, data.Q[rows])
    W = data.board_T_cam[rows] @ np.linalg.inv(base_T_cam)
    out = np.eye(4)
    out[:3, :3] = _orthonormal(W[:, :3, :3].mean(0))
    out[:3, 3] = np.median(W[:, :3, 3], axis=0)
    return out, cam


@dataclass
class SplitResult:
    registration: CalibrationResult
    full: CalibrationResult
    held_pos_rms: dict[str, float]    # m
    held_rot_rms: dict[str, float]    # rad
    held_pos_axes: dict[str, Array]   # m, RMS per board axis (x, y, z)
    train_loo: float = float("nan")   # m, the full fit's leave-one-view-out position RMS on its training views
    camera: str = ""                  # the camera model of CAMERA_CHAIN fit_split_chosen kept


def camera_covariances(res: CalibrationResult, em: ErrorModel, Q: Array,
                        huber: float = 3.5) -> Array:
    """Per-posture 6x6 residual covariance, estimated in the camera frame and rotated to the board.

    A checkerboard pose estimate is much worse along the optical axis (depth) than across it,
    and its position and tilt errors are correlated; a covariance in the camera frame captures
    both, the board-frame residuals of different postures then get different weights.
    Postures whose Mahalanobis residual exceeds `huber` get their covariance inflated
    (Huber IRLS weights): a few views (e.g. the two at 55 deg obliquity, where the board pose
    estimate is poor) must not steer the fit of the arm.
    """
    T = em.poses(res.x[: em.n_params], Q)
    R = T[:, :3, :3]
    r = res.residuals
    rc = np.concatenate([np.einsum("nji,nj->ni", R, r[:, :3]), np.einsum("nji,nj->ni", R, r[:, 3:])], 1)
    w = np.ones(len(rc))
    for _ in range(5):
        S = (rc * w[:, None]).T @ rc / w.sum()
        S += 1e-9 * np.trace(S) * np.eye(6)
        d = np.sqrt(np.einsum("ni,ij,nj->n", rc, np.linalg.inv(S), rc))
        w = np.minimum(1.0, huber / np.maximum(d, 1e-12))
    Rb = np.zeros((len(R), 6, 6))
    Rb[:, :3, :3] = R
    Rb[:, 3:, 3:] = R
    return (Rb @ S @ np.swapaxes(Rb, 1, 2)) / w[:, None, None]


def camera_model(depth_scale: bool = False, board_scale: bool = False,
                 lens: tuple[str, ...] = ()) -> PoseModel | CameraPoseModel | BoardScaleModel:
    if lens:
        return LensModel(corners=FR3_BOARD, half_fov=D405_HALF_FOV, lens=lens)
    return BoardScaleModel() if board_scale else CameraPoseModel() if depth_scale else PoseModel()


def fit_split(data: FR3Data, train: Array, test: Array, prior_angle: float = np.radians(0.5),
              prior_length: float = 5e-3, depth_scale: bool = False, board_scale: bool = False,
              lens: tuple[str, ...] = ()) -> SplitResult:
    """`depth_scale`: the full fit also estimates the camera's depth scale (CameraPoseModel: a
    focal length error scales every view's depth), a term of the camera, not of the arm;
    `board_scale`: the board's pitch along its x and y axes (BoardScaleModel) instead; `lens`:
    the board's pitch and these lens terms (LensModel: the pose estimate's bias from the lens)."""
    kin = fr3_kinematics()
    W0, cam0 = initial_frames(kin, data, train)
    em = ErrorModel.from_kinematics(kin, world=W0, tool=cam0, world_prefix="board",
                                    tool_prefix="cam")
    frames = em.frame_names("world") + em.frame_names("tool")
    meas = data.board_T_cam[train]
    Qt = data.Q[train]
    reg = lm(Problem(em, "pose", Qt, meas, frames, sigma=np.array([1e-3] * 3 + [3e-3] * 3)))
    for _ in range(3):   # re-estimate the noise model from the residuals, refit
        reg = lm(Problem(em, "pose", Qt, meas, frames, cov=camera_covariances(reg, em, Qt), x0=reg.x))
    cands = em.dh_names(with_beta=False) + frames
    probe = Problem(em, "pose", Qt, meas, cands)
    ident = find_identifiable(probe, cands, Q=Qt)
    free = ident.kept
    prior = np.array([np.inf if n in frames else (prior_length if n.split("_")[0] in ("a", "d")
                      else prior_angle) for n in free])
    camera = camera_model(depth_scale, board_scale, lens)
    full = dataclasses.replace(reg, x=np.concatenate([reg.x, camera.extra_nominal]))
    free, prior = free + list(camera.extra_names), np.concatenate([prior, np.full(len(camera.extra_names), np.inf)])
    for _ in range(3):
        block = Block(camera, Qt, meas, cov=camera_covariances(full, em, Qt))
        problem = CompositeProblem(em, [block], free, x0=full.x)
        full = lm(problem, x_prior=problem.nominal(), sigma_prior=prior)
        full = dataclasses.replace(full, residuals=problem.block_residuals(full.x, jacobian=False)[0][0])
    loo = loo_position_rms(problem, full.x, Priors(by_prefix=tuple(zip(free, prior))))
    pos, rot, axes = {}, {}, {}
    for name, res, model in (("registration", reg, PoseModel()), ("full", full, camera)):
        T = model.predict(em.poses(res.x[: em.n_params], data.Q[test]), res.x[em.n_params:])
        st = compare_poses(data.board_T_cam[test], T)
        pos[name] = float(np.sqrt(np.mean(st.pos_norm ** 2)))
        rot[name] = float(np.sqrt(np.mean(np.sum(st.rot ** 2, axis=1))))
        axes[name] = st.rms_pos
    return SplitResult(reg, full, pos, rot, axes, loo)


def fit_split_chosen(data: FR3Data, train: Array, test: Array, chain: tuple[str, ...] = CAMERA_CHAIN) -> SplitResult:
    """fit_split with the camera models of `chain` in turn, each kept over the one kept before
    when it predicts the training views better when each is left out (linearised leave-one-out,
    training views only) by MIN_GAIN; the held-out views take no part."""
    best = None
    for name in chain:
        r = fit_split(data, train, test, board_scale=name == "board", lens=LENS.get(name, ()))
        r.camera = name
        if best is None or r.train_loo < (1.0 - MIN_GAIN) * best.train_loo:
            best = r
    return best


def _kept(results: list[SplitResult]) -> dict[str, int]:
    """How many splits kept each camera model of the chain."""
    counts = Counter(r.camera for r in results)
    return {name: counts[name] for name in CAMERA_CHAIN if counts[name]}


def _count_dh(names: list[str]) -> int:
    return sum(1 for n in names if not n.startswith(("board_", "cam_", "camera_")))


def fr3_study(splits: int = 10, n_train: int = 80, seed: int = 0,
              path: Path = DATA, depth_scale: bool = False, chain: tuple[str, ...] = CAMERA_CHAIN) -> tuple[str, dict]:
    """Each split picks its camera model from `chain` by its training views (fit_split_chosen);
    chain=("rigid",) or `depth_scale` (the focal length term): one model in every split."""
    data = load_fr3(path)
    kin = fr3_kinematics()
    em = ErrorModel.from_kinematics(kin)
    chk = compare_poses(data.base_T_flange, em.poses(em.nominal, data.Q))
    rng = np.random.default_rng(seed)
    N = len(data.Q)
    results = []
    for _ in range(splits):
        perm = rng.permutation(N)
        if not depth_scale:
            results.append(fit_split_chosen(data, perm[:n_train], perm[n_train:], chain))
        else:
            results.append(fit_split(data, perm[:n_train], perm[n_train:], depth_scale=depth_scale))
    lines = [f"FR3 eye-in-hand real data: {N} postures, {splits} random {n_train}/{N - n_train} splits",
             f"nominal model vs controller FK of the flange: max {chk.pos_norm.max() * 1e3:.4f} mm",
             f"full fit estimates {len(results[0].full.free)} parameters: {_count_dh(results[0].full.free)} D-H + "
             f"{sum(n.startswith(('board_', 'cam_')) for n in results[0].full.free)} frame (the other frame parameters "
             f"duplicate joint-1/joint-7 D-H ones) + {sum(n.startswith('camera_') for n in results[0].full.free)} camera",
             "weighted LM, noise covariance estimated in the camera frame, Huber IRLS, weak D-H prior",
             f"camera model kept by the training views' leave-one-out (of {', '.join(chain)}): "
             + ", ".join(f"{k} in {v}" for k, v in _kept(results).items()) + f" of {splits} splits", "",
             f"{'split':<7}{'reg pos mm':>12}{'reg ori deg':>13}{'full pos mm':>13}{'full ori deg':>14}"]
    for k, r in enumerate(results):
        lines.append(f"{k:<7}{r.held_pos_rms['registration'] * 1e3:>12.3f}"
                     f"{np.degrees(r.held_rot_rms['registration']):>13.3f}"
                     f"{r.held_pos_rms['full'] * 1e3:>13.3f}{np.degrees(r.held_rot_rms['full']):>14.3f}")
    med = {f"{w}_{q}": float(np.median([getattr(r, f'held_{q}_rms')[w] for r in results]))
           for w in ("registration", "full") for q in ("pos", "rot")}
    med["full_pos_axes"] = np.median([r.held_pos_axes["full"] for r in results], axis=0)
    med["depth_scale"] = np.array([r.full.estimate.get("camera_depth_scale", np.nan) for r in results])
    med["board_scale"] = np.array([[r.full.estimate.get(f"camera_scale_{a}", np.nan) for a in "xy"] for r in results])
    med["kept"] = _kept(results)
    med["split_pos"] = [r.held_pos_rms["full"] for r in results]
    med["lens"] = [{n[len("camera_"):]: v for n, v in r.full.estimate.items() if n.startswith("camera_")}
                   for r in results]
    lines.append(f"{'median':<7}{med['registration_pos'] * 1e3:>12.3f}{np.degrees(med['registration_rot']):>13.3f}"
                 f"{med['full_pos'] * 1e3:>13.3f}{np.degrees(med['full_rot']):>14.3f}")
    lines.append("(held-out RMS of the position error norm and of the rotation angle)")
    return "\n".join(lines), med


def fr3_floor(splits: int = 10, n_train: int = 80, seed: int = 0, path: Path = DATA) -> float:
    """The floor of fr3_study's figure for a D-H + frames model (m): one fit of every posture (it
    has seen each held-out view) that minimises the position error itself, scored on the held-out
    views of fr3_study's splits, median over the splits. What is left is the checkerboard pose
    noise and what the rigid geometric model cannot describe; a fit of 80 views does not, on
    average, predict the other 34 better than one that has seen them."""
    data = load_fr3(path)
    every = np.arange(len(data.Q))
    start = fit_split(data, every, every[:1])        # fr3_study's fit of every posture: the start
    kin = fr3_kinematics()
    W0, cam0 = initial_frames(kin, data, every)
    em = ErrorModel.from_kinematics(kin, world=W0, tool=cam0, world_prefix="board", tool_prefix="cam")
    position_only = np.array([1e-3] * 3 + [1e3] * 3)       # orientation residuals weightless
    fit = lm(Problem(em, "pose", data.Q, data.board_T_cam, start.full.free, sigma=position_only, x0=start.full.x),
             max_iter=100)
    err = compare_poses(data.board_T_cam, em.poses(fit.x[: em.n_params], data.Q)).pos_norm
    rng = np.random.default_rng(seed)
    return float(np.median([np.sqrt(np.mean(err[rng.permutation(len(every))[n_train:]] ** 2))
                            for _ in range(splits)]))


def fr3_repeatability(path: Path = DATA, tol: float = 0.01) -> tuple[int, float]:
    """Views taken twice at the same posture (every joint within `tol` rad): how many pairs, and
    the RMS over them of the difference of the two measured camera positions beyond what the
    nominal arm (with the frames' starting estimates) predicts for the posture difference (m). The repeatability of the pose estimate
    at one view: held-out error above it is systematic (the pose estimate's bias with the view
    geometry, or the arm), not noise."""
    data = load_fr3(path)
    kin = fr3_kinematics()
    W0, cam0 = initial_frames(kin, data, np.arange(len(data.Q)))
    em = ErrorModel.from_kinematics(kin, world=W0, tool=cam0)
    T = em.poses(em.nominal, data.Q)
    gap = np.abs(data.Q[:, None, :] - data.Q[None, :, :]).max(axis=2)
    pairs = [(i, j) for i in range(len(gap)) for j in range(i + 1, len(gap)) if gap[i, j] <= tol]
    if not pairs:
        return 0, float("nan")
    d = [(data.board_T_cam[i, :3, 3] - data.board_T_cam[j, :3, 3]) - (T[i, :3, 3] - T[j, :3, 3]) for i, j in pairs]
    return len(pairs), float(np.sqrt(np.mean(np.sum(np.square(d), axis=1))))


def fr3_trusted_study(splits: int = 10, n_train: int = 80, seed: int = 0, path: Path = DATA,
                      method: str = "lm", depth_scale: bool = False) -> tuple[str, dict]:
    """The same data through the general pipeline (`calibrate fit`'s trusted fit): a pose block,
    candidates = 28 D-H + both frames, identifiability on the training postures, weak D-H prior,
    plausibility verdict. Registration-only (frames) vs full, per split; held-out position RMS.
    `depth_scale`: the camera's depth scale among the full fit's candidates (CameraPoseModel)."""
    from spacearm.controller.calibration.composite import Block
    from spacearm.controller.calibration.fit_checks import Priors
    from spacearm.controller.calibration.trusted_fit import FitOptions, fit_blocks
    data = load_fr3(path)
    kin = fr3_kinematics()
    N = len(data.Q)
    sigma = [1e-3] * 3 + [np.radians(0.3)] * 3
    priors = Priors(joint_angle=np.radians(0.5), joint_length=5e-3)
    rows, verdicts, scales = [], [], []
    for k in range(splits):
        W0, cam0 = initial_frames(kin, data, np.random.default_rng(seed + k).permutation(N)[:n_train])
        em = ErrorModel.from_kinematics(kin, world=W0, tool=cam0, world_prefix="board", tool_prefix="cam")
        frames = em.frame_names("world") + em.frame_names("tool")
        block = Block(CameraPoseModel() if depth_scale else PoseModel(), data.Q, data.board_T_cam, sigma, label="fr3")
        # Same split for both fits: the options' seed draws it.
        opts = dict(holdout=(N - n_train) / N, seed=seed + k, method=method)
        reg = fit_blocks(em, [block], FitOptions(**opts), candidates=frames)
        full = fit_blocks(em, [block], FitOptions(priors=priors, **opts),
                          candidates=em.dh_names(with_beta=False) + frames + list(block.model.extra_names))
        rows.append((reg.held_rms("after"), full.held_rms("after"), len(full.result.free), full.noise_ratio))
        scales.append(full.estimate.get("camera_depth_scale", np.nan))
        verdicts.append(full.verdict.message())
    lines = [f"FR3 eye-in-hand, general pipeline ({method}): {splits} random {n_train}/{N - n_train} splits,",
             "pose model, identifiability on the training postures, prior 0.5 deg / 5 mm on D-H, stated noise 1 mm / 0.3 deg",
             "", f"{'split':<7}{'frames only mm':>16}{'full mm':>10}{'params':>8}{'resid/noise':>13}  verdict"]
    for k, (r, f, n, q) in enumerate(rows):
        lines.append(f"{k:<7}{r * 1e3:>16.3f}{f * 1e3:>10.3f}{n:>8d}{q:>13.2f}  {verdicts[k]}")
    med = {"registration_pos": float(np.median([r[0] for r in rows])), "full_pos": float(np.median([r[1] for r in rows])),
           "depth_scale": np.array(scales)}
    lines.append(f"{'median':<7}{med['registration_pos'] * 1e3:>16.3f}{med['full_pos'] * 1e3:>10.3f}")
    return "\n".join(lines), med
