"""The diagnosis replays a recording on the recorded arm's drives: the arm file's [joints.drive]
velocity and torque limits and its joint limits, applied as the daemon applies them at bring-up
(controller/daemon/hardware.with_drive_limits), not the ORU test bed's 1 rad/s and 150 N m."""
from __future__ import annotations

import numpy as np
import pytest

from spacearm.base.config.arm import load_arm_config
from spacearm.firmware_sim.plant import PlantConfig
from spacearm.offline.diagnosis.analysis import replay
from spacearm.offline.diagnosis.direct_sim import drive_settings, on_arm_drives, simulate
from spacearm.offline.diagnosis.fit_parameters import apply_fits
from spacearm.offline.diagnosis.recording_io import RecordingTable

UR10 = "configs/arm/ur10.toml"        # joint 1: 2.16 rad/s, 330 N m (its URDF's limits)
DT = 0.02


def _plant(load: float = 0.0) -> PlantConfig:
    """Six independent joints; joint 1 carries a load torque `load` (N m) at q = 0."""
    joint = {"resolver_arcsec": 0.0, "link_inertia": 1.0}
    first = dict(joint, gravity_torque=load)
    return PlantConfig(joints=[first] + [joint] * 5)


def _table(plant: PlantConfig, q_cmd: np.ndarray) -> RecordingTable:
    tr = simulate(plant, q_cmd, DT)
    return RecordingTable(tr.t, tr.q_cmd, tr.q, tr.dq, tr.tau, tr.wrench)


def test_every_replay_carries_the_arms_drive_limits():
    arm = load_arm_config(UR10)
    plant = on_arm_drives(_plant(), UR10)
    settings = drive_settings(apply_fits(plant, []), 6)         # a fitted variant keeps the arm's drives
    for s, joint in zip(settings, arm.joints):
        assert s.max_torque * s.rated_joint_torque == pytest.approx(joint.drive.torque)
        assert s.max_velocity == pytest.approx(joint.drive.velocity)
        assert s.lower < joint.limits.lower and s.upper > joint.limits.upper
    assert "drives" not in plant.model_dump(exclude_defaults=True)       # the fitted plant file stays a plant file


def test_a_load_above_the_test_beds_torque_replays_on_the_imported_arms_drives():
    """A recorded 250 N m hold: the UR10's 330 N m drive holds it; the test bed's 150 N m drive would sag."""
    q_cmd = np.zeros((100, 6))
    recording = _table(on_arm_drives(_plant(250.0), UR10), q_cmd)
    assert recording.tau[-1, 0] == pytest.approx(250.0, rel=0.01)
    on_arm = replay(recording, on_arm_drives(_plant(250.0), UR10))
    on_test_bed = replay(recording, _plant(250.0))
    assert np.max(np.abs(on_arm.tau[10:, 0] - recording.tau[10:, 0])) < 0.5     # after the start transient
    assert abs(on_test_bed.tau[-1, 0]) == pytest.approx(150.0, rel=0.01)     # what today's replay did


def test_a_motion_faster_than_the_test_beds_drives_replays_at_its_own_speed():
    """1.8 rad/s on joint 1 is within the UR10's 2.16 rad/s; the test bed's drives clamp at 1 rad/s."""
    t = DT * np.arange(60)
    q_cmd = np.zeros((60, 6))
    q_cmd[:, 0] = 1.8 * t
    on_arm = simulate(on_arm_drives(_plant(), UR10), q_cmd, DT)
    on_test_bed = simulate(_plant(), q_cmd, DT)
    assert on_arm.q[-1, 0] == pytest.approx(q_cmd[-2, 0], abs=0.1)
    assert on_test_bed.q[-1, 0] < 0.6 * q_cmd[-2, 0]
    assert on_arm.following_error_window == pytest.approx(min(j.drive.following_error
                                                             for j in load_arm_config(UR10).joints))
    assert on_arm.following_error_max > 0.0


def test_record_sim_direct_runs_a_seven_joint_arm_on_its_own_drives(tmp_path):
    """`record-sim --direct` takes the joint count and the drives from --arm (it read 6 joints and
    the test bed's drives for every arm): Panda joint 1 at 1.5 rad/s, above the test bed's 1 rad/s."""
    import subprocess
    import sys
    from spacearm.offline.diagnosis.recording_io import read_table
    t = DT * np.arange(100)
    q = np.zeros((100, 7))
    q[:, 3] = -1.5
    q[:, 0] = np.minimum(1.5 * t, 1.2)
    np.savetxt(tmp_path / "t.csv", np.column_stack([t, q]), delimiter=",", comments="",
               header="t," + ",".join(f"q_cmd_{i}" for i in range(1, 8)))
    out = subprocess.run([sys.executable, "-m", "spacearm.console.main", "record-sim", "--plant",
                          "configs/plant/panda_nominal.toml", "--arm", "configs/arm/panda.toml", "--bus-config",
                          "configs/bus/panda.toml", "--trajectory", str(tmp_path / "t.csv"), "--out",
                          str(tmp_path / "r.csv"), "--direct"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    table = read_table(tmp_path / "r.csv")
    assert table.q.shape[1] == 7
    assert np.max(np.abs(np.diff(table.q[:, 0]))) / DT > 1.3       # moved faster than the test bed's drives allow
