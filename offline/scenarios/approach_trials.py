"""Randomised changeout approaches on the demo plant's arm, open loop vs closed loop on the
same draws (bench/bench_oru.py): why the ORU paper flies subtasks 2 and 8 on vision.

Each trial takes a store placement error (a few mm, about a degree of yaw, tenths of a degree
of tilt; drawn by the changeout_approach campaign, configs/campaigns/changeout_approach.toml,
offline/campaign/kind_approach.py) and then, for the same draw:
- open loop: the nominal model's joints for the nominal pre-contact pose, flown by the true
  arm (configs/plant/oru_cell_errors.toml geometry): the handover error is kinematics;
- closed loop: the approach mode (controller/daemon/approach_mode.py) from the view pose,
  on frames the camera simulator renders from the true arm and the true marker, measured by
  the vision pipeline, with the result arriving `latency_cycles` after the exposure; the drives
  follow their targets exactly (no bus: this is about geometry, the bus runs in the demo).
Both handover errors (lateral and angular, in the slot frame) then start the contact subtask
(capture or insertion) on the contact world (offline/contact/trials.py), whose success and
peak forces decide. The contact trial starts 10 mm above the part: the closed-loop approach
ends 75 mm above it, and the 65 mm in between along the nominal slot axis would add at most
~0.3 mm for the drawn tilts (left out).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from spacearm.base.config.arm import load_arm_config
from spacearm.base.config.scene import load_scene
from spacearm.base.kinematics import KinematicData, KinematicModel, fk, solve_ik
from spacearm.base.spatial import inv_transform, matrix_to_rotvec, xyz_rpy_to_transform
from spacearm.base.vision.config import load_mount
from spacearm.base.vision.frames import Frame
from spacearm.controller.cycle import Measurement
from spacearm.controller.daemon.approach_mode import ApproachMode, marker_T_goal
from spacearm.controller.oru.config import load_changeout
from spacearm.controller.vision.pipeline import VisionPipeline
from spacearm.firmware_sim.camera.simulator import CameraSimulator
from spacearm.firmware_sim.plant import load_plant_config
from spacearm.offline.contact.trials import ContactTrials, TrialResult

DEMO_PLANT = "configs/plant/oru_cell_errors.toml"
ARM = "configs/arm/oru_testbed_6dof.toml"
PERIOD = 0.02


@dataclass
class Placement:
    xyz: tuple[float, float, float]      # m, slot_nominal_T_slot_true
    rpy: tuple[float, float, float]      # rad


@dataclass
class ApproachOutcome:
    handover: tuple[float, float] | None   # (lateral m, angle rad) vs the true goal, slot frame
    contact: TrialResult | None
    failure: str | None = None             # the approach's own failure (vision), if any
    frames: int = 0
    wall_time: float = 0.0

    @property
    def success(self) -> bool:
        return self.contact is not None and self.contact.success


class _DelayedVision:
    """latest() as the VisionWorker gives it, each result released `delay` cycles after exposure."""

    def __init__(self, delay: int):
        self.delay, self.pending, self._latest = delay, [], None

    def add(self, result, sync: int) -> None:
        self.pending.append((sync + self.delay, (result, sync)))

    def tick(self, sync: int) -> None:
        while self.pending and self.pending[0][0] <= sync:
            self._latest = self.pending.pop(0)[1]

    def latest(self):
        return self._latest


class ApproachTrials:
    def __init__(self, plant_file: str = DEMO_PLANT, frame_every: int = 3, latency_cycles: int = 3,
                 seed: int = 1):
        self.arm = load_arm_config(ARM)
        self.model = KinematicModel.from_config(self.arm)
        self.true = load_plant_config(plant_file).geometry.true_model()
        self.scene = load_scene()
        self.changeout = load_changeout()
        self.pipeline = VisionPipeline.from_configs()
        self.camera = CameraSimulator.from_configs(scene_seed=0, noise_seed=seed)
        self.end_T_camera = load_mount().end_T_camera.matrix()
        self.marker_T_oru = self.pipeline.marker.marker_T_oru
        self.contact = ContactTrials()
        self.frame_every, self.latency = frame_every, latency_cycles

    # ---- goals ---------------------------------------------------------------------------
    def _goal(self, base_T_slot: np.ndarray, placing: bool, gap: float) -> np.ndarray:
        g = self.scene.geometry
        base_T_marker = base_T_slot @ g.slot_T_oru() @ inv_transform(self.marker_T_oru)
        return base_T_marker @ marker_T_goal(self.scene, self.marker_T_oru, self._dz(placing, gap),
                                             "held" if placing else None)

    def _dz(self, placing: bool, gap: float) -> float:
        return self.scene.geometry.slot_depth + gap if placing else gap

    def _handover(self, tool: np.ndarray, goal: np.ndarray, base_T_slot: np.ndarray, placing: bool):
        """Lateral (slot x, y) and rotation (slot frame) of the tool against the goal, about the
        part's tip: the start error ContactTrials takes."""
        tip = self.scene.geometry.tool_T_oru() if placing else np.eye(4)
        R_s = base_T_slot[:3, :3]
        lateral = R_s.T @ ((tool @ tip)[:3, 3] - (goal @ tip)[:3, 3])
        rotvec = matrix_to_rotvec(R_s.T @ tool[:3, :3] @ goal[:3, :3].T @ R_s)
        return (float(lateral[0]), float(lateral[1])), tuple(float(v) for v in rotvec)

    def _contact(self, store: str, placing: bool, lateral, rotvec) -> TrialResult:
        return self.contact.run("insert" if placing else "capture", store, lateral, rotvec)

    # ---- the two ways to fly subtask 2/8 -------------------------------------------------
    def open_loop(self, store: str, placing: bool, placement: Placement) -> ApproachOutcome:
        t0 = time.perf_counter()
        nominal = self.scene.store(store).pose.matrix()
        true_slot = nominal @ xyz_rpy_to_transform(placement.xyz, placement.rpy)
        gap = self.changeout.motion.contact_gap
        goal_nominal = self._goal(nominal, placing, gap)
        ik = solve_ik(self.model, KinematicData(self.model), goal_nominal, np.array(self.arm.postures["ready"]))
        tool = fk(self.true, KinematicData(self.true), ik.q)
        lateral, rotvec = self._handover(tool, self._goal(true_slot, placing, gap), true_slot, placing)
        result = self._contact(store, placing, lateral, rotvec)
        return ApproachOutcome((float(np.hypot(*lateral)), float(np.linalg.norm(rotvec))), result,
                               wall_time=time.perf_counter() - t0)

    def closed_loop(self, store: str, placing: bool, placement: Placement, max_cycles: int = 2000) -> ApproachOutcome:
        t0 = time.perf_counter()
        nominal = self.scene.store(store).pose.matrix()
        true_slot = nominal @ xyz_rpy_to_transform(placement.xyz, placement.rpy)
        g = self.scene.geometry
        base_T_marker = true_slot @ g.slot_T_oru() @ inv_transform(self.marker_T_oru)
        gap = self.changeout.motion.approach_gap
        view = self._goal(nominal, placing, gap + self.changeout.motion.view_height)
        q = solve_ik(self.model, KinematicData(self.model), view, np.array(self.arm.postures["ready"])).q
        vision = _DelayedVision(self.latency)
        mode = ApproachMode(self.model, vision, self.end_T_camera,
                            marker_T_goal(self.scene, self.marker_T_oru, self._dz(placing, gap),
                                          "held" if placing else None),
                            self.arm.cartesian, PERIOD, target=store, tuning=self.arm.approach)
        data = KinematicData(self.true)
        prior, frames, out = None, 0, None
        n = self.model.nq
        for sync in range(1, max_cycles + 1):
            vision.tick(sync)
            m = Measurement(sync * PERIOD, sync, q.copy(), np.zeros(n), np.zeros(n), np.ones(n, bool),
                            np.zeros(n, bool), np.zeros(6))
            out = mode.update(sync * PERIOD, m)
            if sync % self.frame_every == 0:          # exposure at this SYNC, from the true arm
                camera_T_marker = inv_transform(fk(self.true, data, q) @ self.end_T_camera) @ base_T_marker
                image = self.camera.render(camera_T_marker, sync * PERIOD).image      # the sensor's gain in the lighting's pass
                result = self.pipeline.process(Frame(sync * PERIOD, sync, image, None, sync), prior)
                prior = result.camera_T_marker if result.ok else None
                vision.add(result, sync)
                frames += 1
            q = out.setpoint.q.copy()                 # ideal drives
            if out.failure is not None or out.finished:
                break
        if out is None or out.failure is not None or not out.finished:
            why = out.failure.message if out is not None and out.failure is not None else "not finished"
            return ApproachOutcome(None, None, why, frames, time.perf_counter() - t0)
        tool = fk(self.true, data, q)
        lateral, rotvec = self._handover(tool, self._goal(true_slot, placing, gap), true_slot, placing)
        result = self._contact(store, placing, lateral, rotvec)
        return ApproachOutcome((float(np.hypot(*lateral)), float(np.linalg.norm(rotvec))), result,
                               frames=frames, wall_time=time.perf_counter() - t0)


__all__ = ["ApproachTrials", "ApproachOutcome", "Placement"]
