"""The ORU changeout as the main job: enable, move to ready, run the task flow (ORU paper
Table 1, four stages), move home, disable; summary per stage from the runner's records.

The final pose errors are the plant's truth when the caller passes the simulator's plant
(the demo does: on hardware a laser tracker would give them); without it they are left out
rather than guessed. Per stage: the approach's (subtask 2 or 8) tool pose error against the
true pre-contact goal at the handover to contact (the plant's true geometry, thermal state
included, at the measured joints), the camera figures of the closed-loop approach and the
contact figures of the impedance steps.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from spacearm.controller.daemon.daemon import Daemon


class ChangeoutFailed(Exception):
    pass


OVERRUNS_SHOWN = 5      # the first overruns of a run described in its notes (each with its cause)
@dataclass
class StageSummary:
    number: int
    name: str
    arm_time: float = 0.0
    peak_force: float = 0.0           # N, compensated contact force
    peak_torque: float = 0.0          # N m
    peak_insert_force: float = 0.0    # N along the insertion axis
    approach: str = ""                # how subtask 2/8 ran: "closed loop (vision)" or "open loop"
    approach_error: tuple[float, float] | None = None   # (m, rad) vs the true goal at the handover
    approach_attempts: int = 0
    frames: int = 0                   # camera results during the closed-loop approach
    detected: int = 0
    latency: float | None = None      # s, median exposure -> use in the cycle (controller time)
    processing: float | None = None   # s, median vision time per frame (wall)


@dataclass
class ChangeoutResult:
    stages: list[StageSummary] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    seat_errors: dict[str, tuple[float, float]] = field(default_factory=dict)  # ORU -> (m, rad) plant truth
    recording: str | None = None
    cycles: int = 0
    stats: dict[str, Any] = field(default_factory=dict)
    wall_time: float = 0.0
    arm_time: float = 0.0


def start_camera(simulator, frame_rate: float | None = None):
    """The simulated plant's eye-in-hand camera rendering into a new shared-memory frame ring;
    returns (ring, name): give the daemon `camera=name`, close the ring after the run."""
    import os
    from spacearm.base.vision.config import load_camera
    from spacearm.base.vision.frames import ShmFrameRing
    cam = load_camera()
    name = f"spacearm-{os.getpid()}-{time.monotonic_ns() % 1000000}"
    ring = ShmFrameRing.create(cam.sensor.width, cam.sensor.height, name=name)
    simulator.attach_camera(ring, frame_rate=frame_rate)
    return ring, name


class _Truth:
    """The plant's true tool pose error against the true pre-contact goal of a store."""

    def __init__(self, daemon: Daemon, plant):
        from spacearm.base.vision.config import load_marker
        from spacearm.base.vision.marker import MarkerModel
        from spacearm.firmware_sim.camera.service import marker_sites
        self.plant, self.daemon = plant, daemon
        self.scene = plant.environment.scene if plant.environment is not None else daemon.oru.scene
        self.marker_T_oru = MarkerModel.from_config(load_marker()).marker_T_oru
        self.sites = {m.store: m for m in marker_sites(self.scene, self.marker_T_oru)}
        self.sync_now, self.time_now = daemon.snapshot.measurement.sync_counter, plant.time

    def error(self, record: dict, store: str) -> tuple[float, float]:
        from spacearm.base.kinematics import KinematicData, fk
        from spacearm.controller.daemon.approach_mode import marker_T_goal
        placing = record["number"] == 8
        g, motion = self.scene.geometry, self.daemon.oru.changeout.motion
        gap = motion.approach_gap if record["vision"] is not None else motion.contact_gap
        dz = g.slot_depth + gap if placing else gap       # as the flow passes it to the approach mode
        goal = self.sites[store].base_T_marker @ marker_T_goal(self.scene, self.marker_T_oru, dz,
                                                               "held" if placing else None)
        # the plant's geometry at the handover's plant time (thermal growth changes it slowly)
        t = self.time_now - (self.sync_now - record["sync_end"]) * self.daemon.options.period
        model = self.plant.config.geometry.true_model(self.plant.config.temperature.delta(t))
        tool = fk(model, KinematicData(model), np.asarray(record["q_end"], float))
        d = np.linalg.inv(goal) @ tool
        return float(np.linalg.norm(d[:3, 3])), float(math.acos(np.clip((np.trace(d[:3, :3]) - 1) / 2, -1.0, 1.0)))


def _approach_figures(s: StageSummary, r: dict, truth: _Truth | None, store: str) -> None:
    s.approach_attempts += 1
    s.approach = "closed loop (vision)" if r["vision"] is not None else "open loop"
    v = r["vision"]
    if v is not None:
        s.frames += v["frames"]
        s.detected += v["detected"]
        if r["outcome"] == "done":
            s.latency, s.processing = v["latency_median"], v["processing_median"]
    if r["outcome"] == "done" and truth is not None and r["q_end"] is not None:
        s.approach_error = truth.error(r, store)


def _wait(daemon: Daemon, done: Callable[[], bool], what: str, timeout: float = 600.0) -> None:
    deadline = time.monotonic() + timeout
    while not done():
        if daemon.snapshot.state == "stopped":
            raise ChangeoutFailed(f"{what}: protective stop: {daemon.snapshot.stop_reason}")
        if time.monotonic() > deadline:
            raise ChangeoutFailed(f"{what}: not done within {timeout:.0f} s")
        time.sleep(0.01)


def run_changeout(daemon: Daemon, on_progress: Callable[[str, float], None], world=None, plant=None,
                  stages: list[int] | None = None) -> ChangeoutResult:
    """Run on a started daemon whose cycle runs on another thread. `plant` (the simulator's)
    gives the approach errors against the truth; `stages` (1-based) runs a part of the flow."""
    result = ChangeoutResult()
    started = time.monotonic()
    lease = daemon.lease.take("changeout")
    call = lambda cmd, **a: daemon.handlers.handle(None, cmd, {**a, "lease": lease})   # noqa: E731
    on_progress("enable drives", 0.0)
    cycle = daemon.snapshot.tick.cycle
    call("enable")
    _wait(daemon, lambda: daemon.snapshot.tick.cycle > cycle + 1 and daemon.snapshot.state == "enabled", "enable")
    motion = call("move_joints", q=list(daemon.arm.postures["ready"]))["motion"]
    _wait(daemon, lambda: daemon.snapshot.motions_finished >= motion, "move to ready")
    t0 = daemon.snapshot.tick.time
    call("oru.run", **({"stages": stages} if stages else {}))
    while True:
        status = call("oru.status")
        if status["state"] not in ("running", "paused") or status.get("pause"):
            break
        if status.get("subtask") is not None:
            on_progress(f"stage {status['stage']} subtask {status['subtask']:2d}: {status['title']}",
                        status["progress"])
        time.sleep(0.05)
    if status["state"] != "done":
        why = status.get("failure") or (status.get("pause") or {}).get("message")
        raise ChangeoutFailed(f"ORU changeout {status['state']}: {why}")
    result.arm_time = daemon.snapshot.tick.time - t0
    names = [s.name for s in daemon.oru.changeout.stages]
    result.stages = [StageSummary(i + 1, n) for i, n in enumerate(names)]
    truth = _Truth(daemon, plant) if plant is not None else None
    for r in status["records"]:
        s = result.stages[r["stage"]]
        s.arm_time += r["duration"]
        s.peak_force = max(s.peak_force, r["peak_force"])
        s.peak_torque = max(s.peak_torque, r["peak_torque"])
        s.peak_insert_force = max(s.peak_insert_force, r["peak_insert_force"])
        if r["number"] in (2, 8):
            _approach_figures(s, r, truth, daemon.oru.changeout.stages[r["stage"]].store)
    result.stages = [s for s in result.stages if s.arm_time > 0]
    result.notes = list(dict.fromkeys(status["notes"]))
    on_progress("changeout done", 1.0)
    motion = call("move_joints", q=list(daemon.arm.postures["home"]))["motion"]
    _wait(daemon, lambda: daemon.snapshot.motions_finished >= motion, "move home")
    call("disable")
    _wait(daemon, lambda: not np.any(daemon.snapshot.measurement.joints_enabled), "disable")
    daemon.lease.release(lease)
    world = world if world is not None else getattr(plant, "environment", None)
    if world is not None:
        for name, o in world.orus.items():
            if o.where == "store":
                rel = np.linalg.inv(world.slots[o.store] @ world.slot_T_oru) @ o.pose
                result.seat_errors[f"{name} in {o.store}"] = (
                    float(np.linalg.norm(rel[:3, 3])), float(math.acos(np.clip(rel[2, 2], -1.0, 1.0))))
    result.recording = str(daemon.recorder.path) if daemon.recorder else None
    result.cycles = daemon.stats.cycles
    result.stats = daemon.stats.summary().as_dict()
    result.notes += [f"overrun: {o.describe()}" for o in daemon.overrun_log[:OVERRUNS_SHOWN]]
    result.wall_time = time.monotonic() - started
    return result
