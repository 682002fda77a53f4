"""Closed-loop approach end to end over real processes: `spacearm sim --camera NAME` (plant
with the arm's geometry errors, camera frames in a shared-memory ring) and `spacearm daemon
--camera NAME` (lockstep, vision worker on the ring) on the loopback CAN hub, driven by the
`spacearm approach` console command. The true final error comes from the simulator's side:
the ground-truth camera_T_marker each frame carries through the ring."""
from __future__ import annotations

import json
import time

import numpy as np
import pytest

from spacearm.base.config.arm import load_arm_config
from spacearm.base.config.scene import load_scene
from spacearm.controller.daemon.approach_mode import marker_T_goal
from spacearm.base.kinematics.inverse import solve_ik
from spacearm.base.kinematics.model import KinematicData, KinematicModel
from spacearm.base.spatial import inv_transform, matrix_to_rotvec, xyz_rpy_to_transform
from spacearm.base.vision.config import load_marker, load_mount
from spacearm.base.vision.frames import ShmFrameRing
from hil_tests.camera_stack import launch_camera_stack
from hil_tests.test_daemon_console import Console

pytestmark = [pytest.mark.hil, pytest.mark.multiprocess]
TARGET, DZ = "exposed", 0.10
PLANT = "configs/plant/oru_testbed_errors.toml"


def start_joints(offset_xyz, offset_rpy) -> list[float]:
    """Nominal IK of a pose offset from the nominal pre-contact pose (what an operator would
    command open loop before switching to the camera)."""
    arm = load_arm_config("configs/arm/oru_testbed_6dof.toml")
    model = KinematicModel.from_config(arm)
    scene, marker_T_oru = load_scene(), load_marker().marker_T_oru.matrix()
    base_T_marker = scene.store(TARGET).pose.matrix() @ scene.geometry.slot_T_oru() @ inv_transform(marker_T_oru)
    goal = base_T_marker @ marker_T_goal(scene, marker_T_oru, DZ, None)
    res = solve_ik(model, KinematicData(model), goal @ xyz_rpy_to_transform(offset_xyz, offset_rpy),
                   arm.postures["ready"])
    assert res.success, res.message
    return [float(v) for v in res.q]


def true_error_from_ring(ring: ShmFrameRing, after_seq: int, timeout: float = 60.0) -> tuple[float, float]:
    """Tool error against the true pre-contact pose from the newest frame, exposed after after_seq.
    In lockstep the camera exposes only while the controller acquires: the newest frame is the
    last of the approach, taken at its end (the arm still, the mode finished)."""
    deadline = time.monotonic() + timeout
    while (frame := ring.latest()) is None or frame.seq <= after_seq or frame.true_camera_T_marker is None:
        assert time.monotonic() < deadline, "no new camera frame"
        time.sleep(0.05)
    scene, marker_T_oru = load_scene(), load_marker().marker_T_oru.matrix()
    # tool_T_truegoal; the mount is the same file on both sides (a calibrated camera)
    err = load_mount().end_T_camera.matrix() @ frame.true_camera_T_marker @ marker_T_goal(scene, marker_T_oru, DZ, None)
    return float(np.linalg.norm(err[:3, 3])), float(np.linalg.norm(matrix_to_rotvec(err[:3, :3])))


def test_approach_command_converges_to_the_true_pre_contact_pose(loopback_hub, launch, tmp_path, time_scale):
    api, camera = launch_camera_stack(loopback_hub, launch, PLANT, "approach")
    op = Console(api, tmp_path / "operator")
    ring = ShmFrameRing.attach(camera)
    try:
        op.run("enable")
        op.run("move", "joints", *map(str, start_joints((0.008, -0.006, -0.04), (0.01, -0.015, 0.02))))
        before = ring.latest().seq if ring.latest() is not None else 0
        out = op.run("approach", TARGET, "--dz", "100mm", "--timeout", str(240 * time_scale), "--json")
        result = json.loads(out.stdout)
        assert result["final"]["state"] == "enabled" and not result["final"].get("stop_reason")
        pos, rot = true_error_from_ring(ring, before)
        assert pos <= 1.0e-3 and rot <= np.radians(0.2), f"{pos * 1e3:.3f} mm / {np.degrees(rot):.3f} deg"
    finally:
        ring.close()
