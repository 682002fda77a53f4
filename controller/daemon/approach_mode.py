"""Closed-loop approach on visual feedback (ORU paper Section 4.2, Figure 12): a reactive Mode.

Factory (registered by the daemon as `mode_factories["approach"]`; the ORU task flow calls it
for subtasks 2 and 8):

    mode_factories["approach"](target: str, dz: float, holding: str | None = None) -> Mode

- target: a store name of the scene file (configs/scene/*.toml). The marker beside that
  store's slot is measured by the eye-in-hand camera.
- dz (m, > 0): stand-off of the pre-contact pose along the target's approach axis, the
  paper's (x, y, z + dz, alpha, beta, gamma).
- holding None: the goal is the tool `dz` above the ORU adapter's top face (tool z along the
  capture direction), i.e. oru_T_tool = oru_tip @ Trans(0, 0, -dz).
  holding = ORU name: the goal puts the held ORU `dz` above its seated pose in the slot
  (the pre-insertion pose), using the scene's tool_T_oru.

Each vision result (camera_T_marker of a frame exposed at SYNC s) gives the goal in the base
frame of the *nominal* model: base_T_goal = FK_nominal(q measured at s) @ end_T_camera @
camera_T_marker @ marker_T_goal. Because the target is static this stays valid however late
the frame arrives, and because it is re-measured from every frame, the arm's absolute error
(true geometry != nominal) cancels as the tool closes in. Each cycle the mode moves the
commanded joints with resolved rates (damped pseudo-inverse of the nominal Jacobian) towards
that goal: a proportional twist, limited in linear/angular velocity and acceleration (the arm
file's [cartesian] limits), with per-joint velocity limits.

It finishes when a frame exposed while the arm was still measures the remaining pose error
below tolerance twice in a row. While vision is doubtful (the newest frame had no pose, or
its result is stale) the mode holds: it decelerates to rest and waits. It fails with a code
(the ORU runner retries the approach a bounded number of times, then pauses the flow) when:
  vision_lost     `lost_frames` consecutive frames without a marker pose (reason given: out of
                  view, too far, ambiguous, no marker)
  camera_stopped  no new frame for `no_frame_timeout` (none since the start, or none since the last)
  frame_stale     `lost_frames` consecutive results exposed more than `stale_after` before use
  too_far         the first measured goal is farther than `max_start_distance` from the tool
  error_grows     the measured remaining error grows beyond its smallest value + margin
`report()` gives the figures the task summary shows (frames, detection rate, latency).
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from spacearm.base.config.arm import CartesianLimits
from spacearm.base.config.scene import SceneConfig
from spacearm.controller.modes import ModeBase
from spacearm.controller.cycle import Finding, FindingCode, Measurement
from spacearm.base.kinematics.jacobian import fk_jacobian
from spacearm.base.kinematics.forward import fk
from spacearm.base.kinematics.model import KinematicData, KinematicModel
from spacearm.base.kinematics.pose_error import twist_error
from spacearm.base.spatial import inv_transform, trans
from spacearm.controller.planning.joint_move import JointSetpoint
from spacearm.controller.planning.resolved_rate import damped_pinv
from spacearm.base.config.limits import ApproachConfig


def marker_T_goal(scene: SceneConfig, marker_T_oru: np.ndarray, dz: float, holding: str | None) -> np.ndarray:
    """Goal tool pose in the marker frame (see the module docstring)."""
    g = scene.geometry
    if holding is None:
        return marker_T_oru @ g.oru_tip() @ trans(0.0, 0.0, -dz)
    return marker_T_oru @ trans(0.0, 0.0, dz) @ inv_transform(g.tool_T_oru())


@dataclass
class ApproachMode(ModeBase):
    model: KinematicModel                  # nominal model (the controller's)
    vision: object                         # VisionWorker-like: latest() -> (result, sync) | None
    end_T_camera: np.ndarray
    marker_T_goal: np.ndarray
    limits: CartesianLimits
    period: float
    target: str = ""
    tuning: ApproachConfig = field(default_factory=ApproachConfig)
    name: str = "approach"
    description: str = ""
    # --- state
    goal: np.ndarray | None = None         # base_T_goal (nominal frame)
    measured_error: tuple[float, float] | None = None   # (m, rad) of the newest frame
    _q: np.ndarray | None = None
    _v: np.ndarray = field(default_factory=lambda: np.zeros(6))
    _history: OrderedDict = field(default_factory=OrderedDict)   # sync -> (q, still)
    _seen: object = None
    _bad_frames: int = 0
    _last_failure: str = ""
    _last_frame_time: float | None = None
    _started_at: float | None = None
    _converged_frames: int = 0
    _done: bool = False
    _failure: Finding | None = None
    _err0: float | None = None
    _err_min: float = np.inf
    _stale_frames: int = 0
    frames_used: int = 0                   # results with a pose that steered the arm
    frames_seen: int = 0                   # fresh results of frames exposed while this mode ran
    frames_stale: int = 0                  # results too old to steer by (not in frames_seen)
    _latency: list = field(default_factory=list)     # cycles from exposure to use
    _processing: list = field(default_factory=list)  # s per frame in the vision worker

    def __post_init__(self) -> None:
        self._data = KinematicData(self.model)
        self._v_joint = np.asarray(self.model.v_max, float)

    # ------------------------------------------------------------------ Mode (update() in ModeBase)
    def _next_setpoint(self, t: float, m: Measurement) -> JointSetpoint:
        if self._q is None:
            self._q = m.q.copy()
            self._started_at = t
        still = bool(np.linalg.norm(self._v[:3]) < self.tuning.still_speed
                     and np.linalg.norm(self._v[3:]) < self.tuning.still_speed)
        self._history[m.sync_counter] = (m.q.copy(), still)
        while len(self._history) > 500:
            self._history.popitem(last=False)
        self._take_vision(t, m.sync_counter)
        if self._failure is not None or self._done:
            self._v[:] = 0.0
            return JointSetpoint(self._q.copy(), np.zeros_like(self._q), np.zeros_like(self._q))
        T_cur, J = fk_jacobian(self.model, self._data, self._q)
        if self.goal is None or self._bad_frames > 0 or self._stale_frames > 0:
            v_des = np.zeros(6)                  # no goal yet, or vision doubtful: come to rest and wait
        else:
            v_des = self.tuning.gain * twist_error(self.goal, T_cur)
        v_des[:3] = _clip_norm(v_des[:3], self.limits.linear_velocity)
        v_des[3:] = _clip_norm(v_des[3:], self.limits.angular_velocity)
        dv = v_des - self._v
        dv[:3] = _clip_norm(dv[:3], self.limits.linear_acceleration * self.period)
        dv[3:] = _clip_norm(dv[3:], self.limits.angular_acceleration * self.period)
        self._v = self._v + dv
        dq = damped_pinv(J, self.tuning.damping) @ self._v
        scale = np.max(np.abs(dq) / self._v_joint)
        if scale > 1.0:
            dq /= scale
            self._v /= scale
        self._q = self._q + dq * self.period
        return JointSetpoint(self._q.copy(), dq, np.zeros_like(dq))

    def _finished(self, t: float) -> bool:
        return self._done

    def _progress(self, t: float) -> float:
        if self._err0 is None or self.measured_error is None or self._err0 <= 0:
            return 0.0
        return float(np.clip(1.0 - self.measured_error[0] / self._err0, 0.0, 1.0))

    # ------------------------------------------------------------------ vision
    def report(self) -> dict:
        """Vision figures of this approach (frames, detection rate, latency) and its last measured error."""
        lat = np.array(self._latency, float) * self.period
        return {
            "frames": self.frames_seen, "detected": self.frames_used, "stale": self.frames_stale,
            "detection_rate": self.frames_used / self.frames_seen if self.frames_seen else 0.0,
            "latency_median": float(np.median(lat)) if len(lat) else None,
            "latency_max": float(lat.max()) if len(lat) else None,
            "processing_median": float(np.median(self._processing)) if self._processing else None,
            "measured_position": None if self.measured_error is None else self.measured_error[0],
            "measured_rotation": None if self.measured_error is None else self.measured_error[1],
        }

    def _take_vision(self, t: float, sync_now: int) -> None:
        latest = self.vision.latest()
        if latest is None or latest is self._seen:
            since = self._started_at if self._last_frame_time is None else self._last_frame_time
            if t - since > self.tuning.no_frame_timeout:
                self._fail(FindingCode.CAMERA_STOPPED, f"no new camera frame for {t - since:.1f} s")
            return
        self._seen = latest
        result, sync = latest
        entry = self._history.get(sync)
        if entry is None:
            # exposed before this mode started (or so long ago that its joints are gone):
            # it still shows the camera is alive, but it cannot steer
            self._last_frame_time = t
            if sync < min(self._history, default=sync):
                self._stale(f"frame exposed {sync_now - sync} cycles ago, before the approach's history")
            return
        self._last_frame_time = t
        self._latency.append(sync_now - sync)
        self._processing.append(getattr(result, "processing_time", 0.0))
        age = (sync_now - sync) * self.period
        if age > self.tuning.stale_after:
            self.frames_stale += 1
            self._stale(f"frame exposed {age:.1f} s before use (> {self.tuning.stale_after:.1f} s)")
            return
        self._stale_frames = 0
        self.frames_seen += 1
        if not result.ok:
            self._bad_frames += 1
            self._last_failure = f"{result.reason}: {result.message}"
            if self._bad_frames >= self.tuning.lost_frames:
                self._fail(FindingCode.VISION_LOST, f"marker lost for {self._bad_frames} frames ({self._last_failure})")
            return
        self._bad_frames = 0
        q_exp, still = entry
        end_T_goal = self.end_T_camera @ result.camera_T_marker @ self.marker_T_goal
        goal = fk(self.model, self._data, q_exp) @ end_T_goal
        pos, rot = float(np.linalg.norm(end_T_goal[:3, 3])), _angle(end_T_goal[:3, :3])
        self.measured_error = (pos, rot)
        self.frames_used += 1
        if self._err0 is None:
            self._err0 = pos
            if pos > self.tuning.max_start_distance:
                self._fail(FindingCode.TOO_FAR, f"target {self.target} is {pos:.3f} m from the tool "
                           f"(> {self.tuning.max_start_distance} m): move closer open-loop first")
                return
        self._err_min = min(self._err_min, pos)
        if pos > self._err_min + self.tuning.grow_margin:
            self._fail(FindingCode.ERROR_GROWS, f"remaining error grew to {pos * 1e3:.1f} mm "
                       f"(smallest {self._err_min * 1e3:.1f} mm)")
            return
        self.goal = goal
        if still and pos < self.tuning.tol_position and rot < self.tuning.tol_rotation:
            self._converged_frames += 1
            if self._converged_frames >= 2:
                self._done = True
        elif still:
            self._converged_frames = 0

    def _stale(self, why: str) -> None:
        self._stale_frames += 1
        if self._stale_frames >= self.tuning.lost_frames:
            self._fail(FindingCode.FRAME_STALE, f"{self._stale_frames} stale results in a row ({why})")

    def _fail(self, code: str, message: str) -> None:
        if self._failure is None:
            self._failure = Finding(code, f"approach to {self.target}: {message}")


def _clip_norm(v: np.ndarray, limit: float) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v * (limit / n) if n > limit else v


def _angle(R: np.ndarray) -> float:
    return float(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)))


def approach_factory(model: KinematicModel, scene: SceneConfig, vision, end_T_camera: np.ndarray,
                     marker_T_oru: np.ndarray, limits: CartesianLimits, period: float,
                     tuning: ApproachConfig | None = None):
    """Builds `mode_factories["approach"]`: (target, dz, holding=None) -> ApproachMode."""
    def make(target: str, dz: float, holding: str | None = None) -> ApproachMode:
        scene.store(target)                                  # KeyError names the known stores
        if holding is not None:
            scene.oru(holding)
        if not (0.0 < dz <= 0.5):
            raise ValueError(f"dz {dz} m outside (0, 0.5] m")
        what = f"holding {holding} to slot {target}" if holding else f"adapter in {target}"
        return ApproachMode(model, vision, end_T_camera, marker_T_goal(scene, marker_T_oru, dz, holding),
                            limits, period, target=target, tuning=tuning or ApproachConfig(),
                            description=f"{what}, stand-off {dz * 1e3:.0f} mm")
    return make
