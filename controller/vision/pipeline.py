"""The marker measurement of the ORU paper (Section 4.2, Figures 13-14) on one frame.

    pipeline = VisionPipeline.from_configs()
    result = pipeline.process(frame, prior=None)     # MarkerPose or VisionFailure
    if result.ok: result.camera_T_marker

Steps: circle candidates (controller/vision/detect.py: Gaussian denoising, T = B + s*sigma,
Canny, centres), identification from the known geometry (identify.py), PnP with LM
refinement (pnp.py), the perspective/distortion correction of the circle centres (the centre
of a projected circle is not the projection of its centre), and the gates that turn doubtful
results into a named failure instead of a wrong pose:

    no_marker    fewer than four marker-like circles, or none of the labellings fits
    too_far      circles too small to measure, or the pose lies beyond max_distance
    too_close    the pose lies nearer than min_distance
    out_of_view  a circle touches the image border, or the prior puts one outside
    ambiguous    a second labelling fits almost as well with a different pose

With a prior camera_T_marker (the previous result) the search runs in a window around the
predicted circles and labels them by proximity; on failure it falls back to the full frame.
Runs on the caller's thread: in the daemon a VisionWorker thread calls it at frame rate,
never the control cycle.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from spacearm.base.vision.camera import CameraModel
from spacearm.base.vision.config import (CameraConfig, MarkerConfig, PipelineConfig, load_camera, load_marker,
                                      load_pipeline)
from spacearm.controller.vision.detect import Candidate, CircleDetector
from spacearm.base.vision.frames import Frame
from spacearm.controller.vision.identify import Hypothesis, hypotheses, match_prior, plate_is_dark
from spacearm.base.vision.marker import MarkerModel
from spacearm.controller.vision.pnp import PnpResult, solve_pnp
from spacearm.base.spatial import matrix_to_rotvec

FAILURES = ("no_marker", "too_far", "too_close", "out_of_view", "ambiguous")
CIRCLE_SAMPLES = 64
MAX_PNP = 32                         # labellings solved per frame (after the cheap tests), best score first
RESOLVE = 3                          # best of them refined before the winner and ambiguity tests


@dataclass(frozen=True)
class MarkerPose:
    camera_T_marker: np.ndarray      # 4x4
    rms_px: float                    # reprojection rms after refinement
    centres_px: np.ndarray           # (4, 2) detected centres in model order
    timestamp: float                 # frame exposure time
    seq: int
    processing_time: float           # s
    ok: bool = True

    @property
    def distance(self) -> float:
        return float(np.linalg.norm(self.camera_T_marker[:3, 3]))


@dataclass(frozen=True)
class VisionFailure:
    reason: str                      # one of FAILURES
    message: str
    timestamp: float
    seq: int
    processing_time: float = 0.0
    ok: bool = False


VisionResult = MarkerPose | VisionFailure


@dataclass
class VisionPipeline:
    camera: CameraModel
    marker: MarkerModel
    cfg: PipelineConfig
    detector: CircleDetector = field(init=False)

    def __post_init__(self) -> None:
        if self.cfg.opencv_threads > 0:
            # process-wide: OpenCV's thread pool cost more than it saved here (pipeline.toml)
            cv2.setNumThreads(self.cfg.opencv_threads)
        self.detector = CircleDetector(self.cfg)
        t = np.linspace(0, 2 * np.pi, CIRCLE_SAMPLES, endpoint=False)
        ring = self.marker.circle_radius * np.column_stack([np.cos(t), np.sin(t), np.zeros_like(t)])
        self._rims = self.marker.points[:, None, :] + ring[None]          # (4, S, 3)

    @classmethod
    def from_configs(cls, camera: CameraConfig | None = None, marker: MarkerConfig | None = None,
                     pipeline: PipelineConfig | None = None) -> "VisionPipeline":
        return cls(CameraModel.from_config(camera or load_camera()),
                   MarkerModel.from_config(marker or load_marker()), pipeline or load_pipeline())

    # ------------------------------------------------------------------ public
    def process(self, frame: Frame, prior: np.ndarray | None = None) -> VisionResult:
        t0 = time.perf_counter()
        result = None
        if prior is not None and self.cfg.track_roi:
            # Tracking: measure the four circles where the prior puts them (four small
            # full-res windows, no search); a doubtful result falls back to the window search
            # and then to the full frame.
            result = self._track(frame, prior)
            if result is None:
                roi = self._roi(prior)
                if roi is not None:
                    result = self._measure(frame, roi, prior)
        if result is None or not result.ok:
            full = self._measure(frame, None, None)
            # keep the more specific reason of the tracked attempt when both fail
            if full.ok or result is None or result.reason == "no_marker":
                result = full
        if not result.ok and prior is not None and result.reason == "no_marker":
            if self._outside(prior):
                result = self._fail(frame, "out_of_view", "the marker is partly out of the image")
        elapsed = time.perf_counter() - t0
        return _with_time(result, elapsed)

    # ------------------------------------------------------------------ steps
    def _measure(self, frame: Frame, roi, prior) -> VisionResult:
        cfg, cam = self.cfg, self.camera
        det = self.detector.detect(frame.image, roi)
        cands = det.candidates
        if len(cands) < 4:
            if det.n_too_small >= 4 - len(cands) and det.n_too_small > 0:
                return self._fail(frame, "too_far", f"{det.n_too_small} circle-like blobs below "
                                  f"{cfg.min_diameter_px} px: marker too far to measure")
            if any(c.touches_border for c in cands):
                return self._fail(frame, "out_of_view", "a marker circle touches the image border")
            return self._fail(frame, "no_marker", f"{len(cands)} marker-like circles found, 4 needed")
        centres_px = np.array([c.centre for c in cands])
        xy = cam.undistort_pixels(centres_px)
        diam = np.array([c.diameter for c in cands])
        hyps: list[Hypothesis] = []
        if prior is not None:
            predicted = self._project_normalised(prior, self.marker.points)
            gate = 4 * (np.median(diam) + 10.0) / cam.focal_px
            h = match_prior(predicted, xy, gate)
            if h is not None:
                hyps = [h]
        if not hyps:
            hyps = hypotheses(self.marker, xy, max_keep=512, depth_range=(0.5 * cfg.min_distance, 1.5 * cfg.max_distance))
            hyps = plate_is_dark(frame.image, centres_px, hyps)[:MAX_PNP]
        # Rank every surviving labelling by one unrefined solve, refine the best few from their
        # own pose. The cheap check: a correct pose reprojects to ~0.1 px, so a best refined fit
        # above check_px means the solver may have missed (SQPnP misses the true pose of the true
        # labelling in ~4 % of close views, AP3P in ~2 %, rarely together): only then the other
        # solver ranks and refines as well. One solver per labelling instead of two.
        fits = self._fits(xy, hyps, self.cfg.solver)
        if not fits or fits[0][0].rms_px > self.cfg.check_px:
            fits = sorted(fits + self._fits(xy, hyps, _other(self.cfg.solver)), key=lambda f: f[0].rms_px)
        if not fits:
            return self._fail(frame, "no_marker", f"{len(cands)} candidates, no labelling gives a pose")
        best, hyp = fits[0]
        if best.rms_px > cfg.max_reprojection_px:
            return self._fail(frame, "no_marker", f"best labelling reprojects to {best.rms_px:.2f} px rms "
                              f"(> {cfg.max_reprojection_px} px): not the marker")
        for other, _ in fits[1:]:
            if other.rms_px < cfg.ambiguity_ratio * max(best.rms_px, 0.05) and _differs(best, other):
                return self._fail(frame, "ambiguous", f"two labellings fit ({best.rms_px:.2f} and "
                                  f"{other.rms_px:.2f} px rms) with different poses")
        picked = [cands[i] for i in hyp.indices]
        return self._finish(frame, xy[list(hyp.indices)], picked, best)

    def _finish(self, frame: Frame, xy4: np.ndarray, picked: list[Candidate], best: PnpResult) -> VisionResult:
        """Border, ellipse-centre correction and distance gates on the identified circles."""
        cfg, cam = self.cfg, self.camera
        if any(c.touches_border for c in picked):
            return self._fail(frame, "out_of_view", "a marker circle touches the image border")
        T = best.camera_T_marker
        if cfg.ellipse_centre_correction:
            for _ in range(2):
                xy_fix = xy4 - self._centre_bias(T)
                r = solve_pnp(self.marker.points, xy_fix, cam.focal_px, cfg.solver, True, guess=T)
                if r is None:
                    break
                best, T = r, r.camera_T_marker
        depth = float(T[2, 3])
        if depth > cfg.max_distance:
            return self._fail(frame, "too_far", f"marker at {depth:.2f} m, beyond {cfg.max_distance} m")
        if depth < cfg.min_distance:
            return self._fail(frame, "too_close", f"marker at {depth:.3f} m, nearer than {cfg.min_distance} m")
        return MarkerPose(T, best.rms_px, np.array([c.centre for c in picked]), frame.timestamp, frame.seq, 0.0)

    def _track(self, frame: Frame, prior: np.ndarray) -> VisionResult | None:
        """The four circles measured in small windows around their predicted positions, LM from
        the prior. None (caller falls back to the search) unless every circle is found with a
        plausible size and the pose passes the cheap check."""
        cam = self.camera
        pc = self.marker.points @ prior[:3, :3].T + prior[:3, 3]
        if (pc[:, 2] <= 0.01).any():
            return None
        uv = cam.project(pc)
        r_px = self.marker.circle_radius * cam.focal_px / pc[:, 2]
        picked = []
        for centre, r in zip(uv, r_px):
            c = self.detector.refine_at(frame.image, centre, r)
            if c is None or not (0.4 * 2 * r <= c.diameter <= 2.5 * 2 * r + 2):
                return None
            picked.append(c)
        xy = cam.undistort_pixels(np.array([c.centre for c in picked]))
        best = solve_pnp(self.marker.points, xy, cam.focal_px, self.cfg.solver, True, guess=prior)
        if best is None or best.rms_px > self.cfg.check_px:
            return None
        return self._finish(frame, xy, picked, best)

    def _fits(self, xy: np.ndarray, hyps: list[Hypothesis], solver: str) -> list[tuple[PnpResult, Hypothesis]]:
        """Labellings ranked by one unrefined solve with `solver`; the best RESOLVE refined by LM
        from their own pose, best first."""
        pts, f = self.marker.points, self.camera.focal_px
        ranked = []
        for h in hyps:
            r = solve_pnp(pts, xy[list(h.indices)], f, solver, False)
            if r is not None:
                ranked.append((r.rms_px, h, r))
        ranked.sort(key=lambda x: x[0])
        fits = []
        for _, h, r in ranked[:RESOLVE]:
            refined = (solve_pnp(pts, xy[list(h.indices)], f, solver, True, guess=r.camera_T_marker)
                       if self.cfg.refine_lm else r)
            fits.append((refined or r, h))
        return sorted(fits, key=lambda fh: fh[0].rms_px)

    def _solve(self, xy: np.ndarray, refine: bool, guess: np.ndarray | None = None) -> PnpResult | None:
        """The configured solver (refined by LM when asked and cfg.refine_lm); the other solver
        too only when the result fails the cheap check (rms above check_px); a guess, when
        given, is one more starting point."""
        refine = refine and self.cfg.refine_lm
        pts, f = self.marker.points, self.camera.focal_px
        tries = [solve_pnp(pts, xy, f, self.cfg.solver, refine)]
        if guess is not None and refine:
            tries.append(solve_pnp(pts, xy, f, self.cfg.solver, True, guess=guess))
        tries = [r for r in tries if r is not None]
        if not tries or min(r.rms_px for r in tries) > self.cfg.check_px:
            other = solve_pnp(pts, xy, f, _other(self.cfg.solver), refine)
            tries += [other] if other is not None else []
        return min(tries, key=lambda r: r.rms_px) if tries else None

    def _centre_bias(self, T: np.ndarray) -> np.ndarray:
        """Normalised-image offset between the centroid of each projected circle (what the
        detector measures, distortion included) and the projection of its centre."""
        cam = self.camera
        rims = self._rims @ T[:3, :3].T + T[:3, 3]
        centres = self.marker.points @ T[:3, :3].T + T[:3, 3]
        rim_px = cam.project(rims.reshape(-1, 3)).reshape(4, CIRCLE_SAMPLES, 2)
        area_c = np.array([_polygon_centroid(p) for p in rim_px])
        centre_px = cam.project(centres)
        return cam.undistort_pixels(area_c) - cam.undistort_pixels(centre_px)

    def _project_normalised(self, T: np.ndarray, pts: np.ndarray) -> np.ndarray:
        pc = pts @ T[:3, :3].T + T[:3, 3]
        return pc[:, :2] / pc[:, 2:3]

    def _outside(self, prior: np.ndarray) -> bool:
        pc = self.marker.points @ prior[:3, :3].T + prior[:3, 3]
        if (pc[:, 2] <= 0).any():
            return True
        return not self.camera.in_image(self.camera.project(pc), self.cfg.border_margin_px).all()

    def _roi(self, prior: np.ndarray):
        pc = self.marker.points @ prior[:3, :3].T + prior[:3, 3]
        if (pc[:, 2] <= 0.01).any():
            return None
        uv = self.camera.project(pc)
        r = self.marker.circle_radius * self.camera.focal_px / pc[:, 2].min()
        span = np.ptp(uv, axis=0).max()
        m = 0.3 * span + 6 * r + 24
        W, H = self.camera.width, self.camera.height
        x0, y0 = int(max(0, uv[:, 0].min() - m)), int(max(0, uv[:, 1].min() - m))
        x1, y1 = int(min(W, uv[:, 0].max() + m)), int(min(H, uv[:, 1].max() + m))
        if x1 - x0 < 64 or y1 - y0 < 64:
            return None
        return (x0, y0, x1, y1)

    @staticmethod
    def _fail(frame: Frame, reason: str, message: str) -> VisionFailure:
        return VisionFailure(reason, message, frame.timestamp, frame.seq)


def _other(solver: str) -> str:
    """The second solver of the cheap check."""
    return "sqpnp" if solver == "ap3p" else "ap3p"


def _polygon_centroid(p: np.ndarray) -> np.ndarray:
    x, y = p[:, 0], p[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    c = x * yn - xn * y
    a = c.sum() / 2
    if abs(a) < 1e-12:
        return p.mean(axis=0)
    return np.array([((x + xn) * c).sum(), ((y + yn) * c).sum()]) / (6 * a)


def _differs(a: PnpResult, b: PnpResult) -> bool:
    dT = np.linalg.inv(a.camera_T_marker) @ b.camera_T_marker
    return bool(np.linalg.norm(dT[:3, 3]) > 0.005 or np.linalg.norm(matrix_to_rotvec(dT[:3, :3])) > np.radians(2))


def _with_time(r: VisionResult, elapsed: float) -> VisionResult:
    from dataclasses import replace
    return replace(r, processing_time=elapsed)
