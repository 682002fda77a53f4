"""The arm with mixed drive models (configs/bus/arm_mixed.toml) over each bus transport, the
simulator in its own process on loopback/socketcan: boot from each drive's EDS, enable, move."""
from __future__ import annotations

import pytest

from spacearm.base.config.bus import DEFAULT_BUS_CONFIG, load_bus_config
from spacearm.drivers.network import ArmNetwork
from hil_tests.test_canopen_arm import start_sim  # noqa: F401  (fixture)

pytestmark = pytest.mark.hil
MIXED = DEFAULT_BUS_CONFIG.parent / "arm_mixed.toml"


def test_mixed_drive_arm_boots_enables_and_moves(bus_spec, start_sim, time_scale):  # noqa: F811
    cfg = load_bus_config(MIXED)
    start_sim(cfg)
    net = ArmNetwork(bus_spec, cfg)
    try:
        net.boot(cfg.bus.boot_timeout * time_scale)
        assert "no 1016h" in net.bringup["joint_6"].guarding
        start = net.enable_all().joint_positions
        goal = [q + 0.05 for q in start]
        state = net.move_to(goal, 0.6, settle_cycles=25)
        assert state.joint_positions == pytest.approx(goal, abs=2e-3)
        net.shutdown()
    finally:
        net.close()


@pytest.mark.slow
def test_main_job_checkout_runs_on_the_mixed_drive_arm(tmp_path):
    """The whole stack (simulator, daemon, planner, supervision) through the functional checkout."""
    import subprocess
    import sys

    from spacearm.base.runtime.child_process import module_env

    out = subprocess.run([sys.executable, "-m", "spacearm.console.main", "demo", "--job", "checkout", "--clock", "lockstep",
                          "--bus-config", str(MIXED), "--record-dir", str(tmp_path)],
                         capture_output=True, text=True, timeout=240, env=module_env())
    assert out.returncode == 0, out.stderr[-2000:]
    assert "disable drives" in out.stdout
