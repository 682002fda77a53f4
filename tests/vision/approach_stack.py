"""In-process stack for the closed-loop approach: simulated nodes with the camera on a plant
with geometry errors, the daemon with the vision worker, lockstep clock, virtual bus.

threaded=False steps the daemon's cycle on the caller's thread and only while a command waits
for it or a condition is awaited: every command then starts at the same cycle in every run,
so two runs of the same script are identical to the bit (the lockstep camera is triggered in
plant time and measured in the cycle, controller/vision/lockstep.py)."""
from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from spacearm.base.config.scene import load_scene
from spacearm.controller.daemon.approach_mode import marker_T_goal
from spacearm.controller.daemon.daemon import Daemon, DaemonOptions
from spacearm.base.kinematics.inverse import solve_ik
from spacearm.base.kinematics.model import KinematicData
from spacearm.base.spatial import matrix_to_rpy
from spacearm.base.vision.frames import LocalFrameSource
from spacearm.base.config.bus import DEFAULT_BUS_CONFIG
from spacearm.firmware_sim.camera.service import marker_sites
from spacearm.firmware_sim.runner import start_simulator
from tests.daemon.lockstep_script import call_between_cycles

PLANT = "configs/plant/oru_testbed_errors.toml"


class ApproachStack:
    def __init__(self, plant: str = PLANT, threaded: bool = True):
        self.bus = f"virtual:approach-{time.monotonic_ns()}"
        # SYNC time beside the lockstep daemon: on the wall clock a starved run saw heartbeats
        # lost (EMCY 8130) and two runs of one script parted by a SYNC
        self.sim = start_simulator(self.bus, DEFAULT_BUS_CONFIG, plant, time_base="sync")
        self.frames = LocalFrameSource()
        self.camera = self.sim.attach_camera(self.frames)
        self.daemon = Daemon(DaemonOptions(bus=self.bus, clock="lockstep", api=None, record_dir=None))
        self.daemon.start()
        self.daemon.attach_vision(self.frames)
        self.thread = None
        if threaded:
            self.thread = threading.Thread(target=self.daemon.run, name="control-cycle", daemon=True)
            self.thread.start()
        self.lease = self.daemon.lease.take("test")
        self.scene = load_scene()

    def call(self, cmd: str, **args):
        return self._stepped(lambda: self.daemon.handlers.handle(None, cmd, {**args, "lease": self.lease}))

    def _stepped(self, command):
        """Run `command` (which waits for the cycle); unthreaded, cycle only while it waits."""
        if self.thread is not None:
            return command()
        with ThreadPoolExecutor(1, thread_name_prefix="approach-api") as api:
            return call_between_cycles(self.daemon, api, command)

    def wait(self, predicate, timeout: float = 300.0, poll: float = 0.02):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            value = predicate()
            if value:
                return value
            if self.thread is None:
                self.daemon.cycle_once()
            else:
                time.sleep(poll)
        raise TimeoutError("condition not reached")

    def wait_motion(self, motion: int, timeout: float = 300.0) -> None:
        self.wait(lambda: self.daemon.snapshot.motions_finished >= motion or self.daemon.core.state == "stopped",
                  timeout)

    def enable(self) -> None:
        self.call("enable")
        self.wait(lambda: self.daemon.snapshot.state == "enabled", 10)

    def nominal_goal(self, target: str, dz: float, holding: str | None = None) -> np.ndarray:
        """base_T_tool of the pre-contact pose from the scene's *nominal* store pose."""
        marker = self.daemon.vision.pipeline.marker
        store = self.scene.store(target)
        base_T_marker = store.pose.matrix() @ self.scene.geometry.slot_T_oru() @ np.linalg.inv(marker.marker_T_oru)
        return base_T_marker @ marker_T_goal(self.scene, marker.marker_T_oru, dz, holding)

    def true_goal(self, target: str, dz: float, holding: str | None = None) -> np.ndarray:
        marker = self.daemon.vision.pipeline.marker
        site = next(s for s in marker_sites(self.scene, marker.marker_T_oru) if s.store == target)
        return site.base_T_marker @ marker_T_goal(self.scene, marker.marker_T_oru, dz, holding)

    def move_joints_to(self, T: np.ndarray) -> None:
        """Joint move (nominal IK from the ready posture) to the tool pose T: no straight line,
        so no singularity on the way from home."""
        model = self.daemon.model
        res = solve_ik(model, KinematicData(model), T, self.daemon.arm.postures["ready"])
        assert res.success, res.message
        motion = self.call("move_joints", q=[float(v) for v in res.q])["motion"]
        self.wait_motion(motion)
        assert self.daemon.core.state == "enabled", self.daemon.core.stop_reason

    def move_pose(self, T: np.ndarray) -> None:
        motion = self.call("move_pose", xyz=[float(v) for v in T[:3, 3]],
                           rpy=[float(v) for v in matrix_to_rpy(T[:3, :3])], frame="base")["motion"]
        self.wait_motion(motion)
        assert self.daemon.core.state == "enabled", self.daemon.core.stop_reason

    def approach(self, target: str, dz: float, holding: str | None = None, timeout: float = 300.0) -> dict:
        core = self.daemon.core

        def begin(t, m):
            mode = self.daemon.mode_factories["approach"](target, dz, holding)
            return core.start_planned(t, m, mode, None)

        motion = self._stepped(lambda: self.daemon.handlers._in_cycle(begin))["motion"]
        self.wait_motion(motion, timeout)
        return {"state": core.state, "stop_reason": core.stop_reason}

    def close(self) -> None:
        self.daemon.request_stop()
        if self.thread is not None:
            self.thread.join(timeout=5)
        self.daemon.shutdown()
        self.sim.stop()
