"""Per-joint drive limits from the arm file reach supervision (following-error window per joint)."""
import numpy as np

from spacearm.base.config.arm import load_arm_config
from spacearm.controller.cycle import Measurement
from spacearm.controller.daemon.supervision import SupervisionLimits, Supervisor


def measurement(q: np.ndarray) -> Measurement:
    n = len(q)
    return Measurement(time=0.0, sync_counter=0, q=q, dq=np.zeros(n), tau=np.zeros(n),
                       joints_enabled=np.ones(n, bool), joints_faulted=np.zeros(n, bool), wrench=np.zeros(6))


def test_following_error_window_is_per_joint() -> None:
    n = 3
    limits = SupervisionLimits(np.full(n, -3.0), np.full(n, 3.0), np.ones(n),
                               following_error=np.array([0.005, 0.02, 0.02]))
    supervisor = Supervisor(limits, ["j1", "j2", "j3"])
    findings = supervisor.check(measurement(np.full(n, 0.01)), np.zeros(n), moving=True)
    assert [f.code for f in findings] == ["following_error"]
    assert findings[0].message.startswith("j1:") and "0.0050 rad" in findings[0].message


def test_imported_arm_files_carry_drive_limits_from_the_urdf() -> None:
    ur10 = load_arm_config("configs/arm/ur10.toml")
    assert [j.drive.torque for j in ur10.joints] == [330.0, 330.0, 150.0, 54.0, 54.0, 54.0]
    assert all(j.drive.velocity > j.limits.velocity for j in ur10.joints)
    oru = load_arm_config("configs/arm/oru_testbed_6dof.toml")   # the test bed's drives by default
    assert {(j.drive.velocity, j.drive.torque) for j in oru.joints} == {(1.0, 150.0)}
