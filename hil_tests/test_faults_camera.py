"""Camera faults mid-approach (controller/daemon/approach_mode.py), at the controller core:
the closed-loop approach runs inside ControllerCore with a vision source that first sees the
marker and then loses it (bad frames), stops delivering frames, or delivers results of old
exposures. Expected: the arm holds still meanwhile, then a protective stop `vision_lost` after
`lost_frames` bad frames (6 cycles at one frame per cycle), `camera_stopped` after
`no_frame_timeout` (10 s) without frames, `frame_stale` after `lost_frames` results older than
`stale_after`; no new setpoints afterwards, motion refused until reset. (Inside the ORU flow the
runner retries the approach and then pauses instead: tests/oru/test_vision_failures.py.) Core level (no bus): the camera is not yet a process of the HIL stack."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

pytestmark = pytest.mark.hil

PERIOD = 0.02


class FakeVision:
    """latest() -> (result, sync) like the VisionWorker; the test sets what it sees."""

    def __init__(self):
        self.mode = "marker"      # "marker" | "lost" | "stopped" | "stale"
        self.sync = None
        self._latest = None
        self.lag = 0              # "stale": results of frames exposed this many SYNCs earlier

    def expose(self, sync: int) -> None:
        if self.mode == "stale":
            T = np.eye(4)
            T[2, 3] = 0.10
            self._latest = (SimpleNamespace(ok=True, camera_T_marker=T), sync - self.lag)
        elif self.mode == "marker":
            T = np.eye(4)
            T[2, 3] = 0.10                         # goal 100 mm ahead along the camera axis
            self._latest = (SimpleNamespace(ok=True, camera_T_marker=T), sync)
        elif self.mode == "lost":
            self._latest = (SimpleNamespace(ok=False, reason="no_marker", message="marker out of view"), sync)

    def latest(self):
        return self._latest


@pytest.fixture
def cell():
    from spacearm.base.config.arm import load_arm_config
    from spacearm.controller.daemon.approach_mode import ApproachMode
    from spacearm.controller.daemon.core import ControllerCore
    from spacearm.controller.cycle import Measurement
    from spacearm.controller.daemon.supervision import SupervisionLimits, Supervisor
    from spacearm.base.kinematics.model import KinematicModel

    arm = load_arm_config("configs/arm/oru_testbed_6dof.toml")
    model = KinematicModel.from_config(arm)
    names = list(model.joint_names)
    core = ControllerCore(Supervisor(SupervisionLimits(np.array(model.q_min), np.array(model.q_max),
                                                       np.array(model.v_max)), names), names, PERIOD)
    vision = FakeVision()
    q = np.array(arm.postures["ready"], float)
    state = {"q": q, "sync": 0, "t": 0.0}

    def measure():
        state["sync"] += 1
        state["t"] += PERIOD
        return Measurement(state["t"], state["sync"], state["q"].copy(), np.zeros(6), np.zeros(6),
                           np.ones(6, bool), np.zeros(6, bool), np.zeros(6))

    def cycle():
        m = measure()
        cmd = core.update(m)
        if cmd.enable:
            state["q"] = cmd.q.copy()             # ideal drives: follow the target
        vision.expose(m.sync_counter)             # a frame exposed at this SYNC, seen next cycle
        return cmd

    core.cmd_enable(0.0, measure())
    cycle()
    assert core.state == "enabled"
    mode = ApproachMode(model, vision, np.eye(4), np.eye(4), arm.cartesian, PERIOD, target="store_a")
    core.start_planned(state["t"], measure(), mode, None)
    return SimpleNamespace(core=core, vision=vision, cycle=cycle, state=state, mode=mode)


def run_until_stopped(cell, max_cycles: int) -> int:
    for n in range(1, max_cycles + 1):
        cell.cycle()
        if cell.core.state == "stopped":
            return n
    raise AssertionError(f"no stop within {max_cycles} cycles (mode {cell.core.mode})")


def assert_nothing_moves_until_reset(cell) -> None:
    from spacearm.controller.daemon.core import CommandRefused
    q = cell.state["q"].copy()
    for _ in range(20):
        assert not cell.cycle().enable
    assert np.array_equal(cell.state["q"], q)
    with pytest.raises(CommandRefused, match="reset first"):
        cell.core.cmd_enable(cell.state["t"], None)


def test_marker_lost_mid_approach_stops_within_lost_frames(cell):
    for _ in range(25):                            # approaching on good frames
        cell.cycle()
    assert cell.core.state == "enabled" and cell.mode.frames_used > 10
    cell.vision.mode = "lost"
    cycles = run_until_stopped(cell, 20)
    assert cycles <= cell.mode.tuning.lost_frames + 2
    assert cell.core.stop_reason.code == "vision_lost" and "marker lost" in cell.core.stop_reason.message
    assert_nothing_moves_until_reset(cell)


def test_camera_stopping_mid_approach_stops_after_the_frame_timeout(cell):
    for _ in range(25):
        cell.cycle()
    cell.vision.mode = "stopped"                   # latest() keeps returning the old frame
    timeout_cycles = round(cell.mode.tuning.no_frame_timeout / PERIOD)
    cycles = run_until_stopped(cell, timeout_cycles + 10)
    assert timeout_cycles - 2 <= cycles <= timeout_cycles + 3
    assert cell.core.stop_reason.code == "camera_stopped" and "no new camera frame" in cell.core.stop_reason.message
    assert_nothing_moves_until_reset(cell)


def test_stale_results_mid_approach_hold_the_arm_then_stop(cell):
    for _ in range(25):
        cell.cycle()
    cell.vision.mode = "stale"
    cell.vision.lag = round(1.5 * cell.mode.tuning.stale_after / PERIOD)   # a worker 4.5 s behind
    speeds = [np.linalg.norm(cell.mode._v[:3])]
    for _ in range(cell.mode.tuning.lost_frames - 2):
        cell.cycle()
        speeds.append(np.linalg.norm(cell.mode._v[:3]))
    # it decelerates towards rest (at the Cartesian acceleration limit) instead of steering by old frames
    decel = cell.mode.limits.linear_acceleration * PERIOD
    assert cell.core.state == "enabled" and speeds[0] > 0
    # (the first cycle still uses the last good frame, exposed before the switch)
    assert all(b <= max(a - 0.9 * decel, 0.0) + 1e-12 for a, b in zip(speeds[1:], speeds[2:])), speeds
    cycles = run_until_stopped(cell, 20)
    assert cycles <= 4
    assert cell.core.stop_reason.code == "frame_stale"
    assert_nothing_moves_until_reset(cell)
