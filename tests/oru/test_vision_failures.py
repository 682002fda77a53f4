"""Camera failures during the changeout's closed-loop approach (subtask 2), inside the task
runner and the controller core without plant or bus: marker lost, camera stopped, stale
results. Each time the approach holds the arm, the runner retries it `approach_retries`
times after `retry_hold`, then pauses the flow with the code (no protective stop: the drives
stay enabled and the arm holds); resume starts a fresh approach, which completes once the
camera sees the marker again."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from spacearm.base.config.arm import load_arm_config
from spacearm.base.config.scene import load_scene
from spacearm.base.kinematics import KinematicData, KinematicModel, fk
from spacearm.controller.cycle import Measurement
from spacearm.controller.daemon.approach_mode import approach_factory, marker_T_goal
from spacearm.controller.daemon.core import ControllerCore
from spacearm.controller.daemon.supervision import SupervisionLimits, Supervisor
from spacearm.controller.impedance.config import load_impedance
from spacearm.controller.modes import HoldMode
from spacearm.controller.oru.config import load_changeout
from spacearm.controller.oru.flow import FlowContext
from spacearm.controller.oru.runner import OruTaskRunner
from spacearm.controller.planning.motion_planner import MotionPlanner

ARM = load_arm_config("configs/arm/oru_testbed_6dof.toml")
MODEL = KinematicModel.from_config(ARM)
READY = np.array(ARM.postures["ready"])
PERIOD = 0.02


class FakeCamera:
    """latest() -> (result, sync) as the VisionWorker gives it; one frame per cycle."""

    def __init__(self):
        self.mode = "marker"          # marker | lost | stopped | stale
        self.goal_distance = 0.004    # m: the marker puts the goal this far ahead of the tool
        self.marker_T_goal = np.eye(4)
        self._latest = None

    def expose(self, sync: int, remaining: float) -> None:
        T = np.eye(4)
        T[2, 3] = remaining
        T = T @ np.linalg.inv(self.marker_T_goal)       # camera_T_marker that puts the goal there
        if self.mode == "marker":
            self._latest = (SimpleNamespace(ok=True, camera_T_marker=T, processing_time=0.002), sync)
        elif self.mode == "lost":
            self._latest = (SimpleNamespace(ok=False, reason="no_marker", message="marker out of view"), sync)
        elif self.mode == "stale":
            self._latest = (SimpleNamespace(ok=True, camera_T_marker=T, processing_time=0.002), sync - 400)

    def latest(self):
        return self._latest


class Cell:
    """Core + runner at subtask 2 of stage 1, ideal drives, a camera looking along the tool axis."""

    def __init__(self):
        self.camera = FakeCamera()
        factory = approach_factory(MODEL, load_scene(), self.camera, np.eye(4), np.eye(4), ARM.cartesian,
                                   PERIOD, ARM.approach)
        ctx = FlowContext(MODEL, MotionPlanner(MODEL, PERIOD, ARM.cartesian), load_scene(), load_changeout(),
                          load_impedance(), {"approach": factory}, READY.copy())
        self.runner = OruTaskRunner(ctx, stages=[0])
        self.camera.marker_T_goal = marker_T_goal(ctx.scene, np.eye(4), ctx.gap(), None)   # as the flow asks (capture)
        self.runner.index = 1
        assert self.runner.steps[1].number == 2
        self.core = ControllerCore(Supervisor(SupervisionLimits(np.array(MODEL.q_min), np.array(MODEL.q_max),
                                                                np.array(MODEL.v_max)), list(MODEL.joint_names)),
                                   list(MODEL.joint_names), PERIOD)
        self.core.state = "enabled"
        self.core.mode = HoldMode(READY.copy())
        self.q, self.t, self.sync = READY.copy(), 0.0, 0
        self.data = KinematicData(MODEL)
        self.start_z = fk(MODEL, self.data, self.q)[:3, 3].copy()
        self.core.start_planned(0.0, self.measurement(), self.runner, None)

    def measurement(self) -> Measurement:
        self.sync += 1
        n = MODEL.nq
        return Measurement(self.t, self.sync, self.q.copy(), np.zeros(n), np.zeros(n), np.ones(n, bool),
                           np.zeros(n, bool), np.zeros(6), end_effector="open")

    def cycle(self):
        m = self.measurement()
        command = self.core.update(m)
        if command.enable:
            self.q = command.q.copy()
        travelled = np.linalg.norm(fk(MODEL, self.data, self.q)[:3, 3] - self.start_z)
        self.camera.expose(m.sync_counter, max(self.camera.goal_distance - travelled, 0.0))
        self.t += PERIOD
        return command

    def run_until(self, predicate, max_cycles: int) -> int:
        for n in range(1, max_cycles + 1):
            self.cycle()
            assert self.core.state == "enabled", self.core.stop_reason   # never a protective stop
            if predicate():
                return n
        raise AssertionError(f"not reached in {max_cycles} cycles: runner {self.runner.status()['state']}")


def bound_cycles(cell: Cell, code: str) -> int:
    """Cycles the approach may hold before it gives up with `code` (the arm file's [approach])."""
    tuning = ARM.approach
    per_attempt = (round(tuning.no_frame_timeout / PERIOD) if code == "camera_stopped" else tuning.lost_frames) + 3
    vision = cell.runner.ctx.config.vision
    return (vision.approach_retries + 1) * per_attempt + vision.approach_retries * round(vision.retry_hold / PERIOD) + 10


@pytest.mark.parametrize("fault, code", [("lost", "vision_lost"), ("stopped", "camera_stopped"),
                                         ("stale", "frame_stale")])
def test_camera_failure_in_the_approach_holds_retries_then_pauses_with_the_code(fault, code):
    cell = Cell()
    cell.run_until(lambda: cell.runner.records and cell.runner.records[-1].number == 2, 5)
    for _ in range(10):
        cell.cycle()                                    # approaching on good frames
    cell.camera.mode = fault
    cell.run_until(lambda: cell.runner.state == "paused", bound_cycles(cell, code))
    status = cell.runner.status()
    retries = cell.runner.ctx.config.vision.approach_retries
    assert status["pause"]["code"] == code and "paused" in status["pause"]["message"]
    attempts = [r["outcome"] for r in status["records"] if r["number"] == 2]
    assert attempts == ["retried"] * retries + ["paused"]
    assert status["subtask"] == 2 and status["failure"] is None
    q = cell.q.copy()
    for _ in range(50):                                 # paused: drives enabled, the arm holds
        assert cell.cycle().enable
    assert np.array_equal(cell.q, q)
    # the camera is back: resume starts a fresh approach, which completes the subtask
    cell.camera.mode = "marker"
    assert cell.runner.resume() == "running" and cell.runner.status()["pause"] is None
    cell.run_until(lambda: cell.runner.index > 1, 1500)
    done = cell.runner.records[-1]
    assert done.number == 2 and done.outcome == "done"
    assert done.vision["frames"] > 0 and done.vision["detection_rate"] == 1.0


def test_a_short_marker_dropout_is_ridden_out_without_a_retry():
    cell = Cell()
    cell.run_until(lambda: cell.runner.records and cell.runner.records[-1].number == 2, 5)
    cell.camera.mode = "lost"
    for _ in range(ARM.approach.lost_frames - 2):
        cell.cycle()
    cell.camera.mode = "marker"
    cell.run_until(lambda: cell.runner.index > 1, 1500)
    assert [r.outcome for r in cell.runner.records if r.number == 2] == ["done"]
    assert cell.runner.records[-1].vision["detection_rate"] < 1.0
