"""Arms imported from URDF (UR10, 6 joints; Panda, 7 joints) and the ORU test bed run the functional checkout on the
simulated bus: boot, enable, joint and Cartesian moves, disable, with the coupled rigid-body
plant, and their recordings export with one column per joint."""
from __future__ import annotations

import csv
import threading
import time

import pytest

from spacearm.controller.daemon.daemon import Daemon, DaemonOptions
from spacearm.controller.recording.csv_export import export_csv
from spacearm.offline.scenarios.checkout import run_checkout
from spacearm.firmware_sim.runner import start_simulator

ARMS = {"ur10": 6, "panda": 7, "oru_testbed": 6}
FILES = {   # arm: (arm file, bus file, plant file)
    "ur10": ("configs/arm/ur10.toml", "configs/bus/ur10.toml", "configs/plant/ur10_nominal.toml"),
    "panda": ("configs/arm/panda.toml", "configs/bus/panda.toml", "configs/plant/panda_nominal.toml"),
    # the paper's test bed with its estimated link inertials, on the ground (9.81 m/s^2)
    "oru_testbed": ("configs/arm/oru_testbed_6dof.toml", "configs/bus/arm.toml",
                    "configs/plant/oru_testbed_ground.toml"),
}


@pytest.mark.slow
@pytest.mark.parametrize("arm", sorted(ARMS))
def test_arm_runs_checkout_on_virtual_bus_with_rigid_body_plant(arm: str, tmp_path) -> None:
    arm_file, bus_file, plant_file = FILES[arm]
    bus = f"virtual:imported-{arm}-{time.monotonic_ns()}"
    simulator = start_simulator(bus, bus_file, plant_file, time_base="sync")
    daemon = None
    try:
        assert simulator.plant.dynamics is not None   # coupled rigid-body plant, not per joint
        daemon = Daemon(DaemonOptions(bus=bus, arm=arm_file, bus_config=bus_file,
                                      clock="lockstep", api=None, record_dir=tmp_path))
        daemon.start()
        assert daemon.hardware.node_count == ARMS[arm] + 2   # drives + end-effector + F/T sensor
        cycle = threading.Thread(target=daemon.run, daemon=True)
        cycle.start()
        result = run_checkout(daemon, lambda *_: None)
        daemon.request_stop()
        cycle.join(timeout=10)
    finally:
        if daemon is not None:
            daemon.request_stop()
            daemon.shutdown()
        simulator.stop()
    names = [s.name for s in result.steps]
    assert any("Cartesian" in n for n in names) and any("joint move" in n for n in names)
    # m: on orbit the tool ends where the plan put it; on the ground the drives' PD servos sag
    # under gravity (no integral action), 3.6 mm at the test bed's home posture
    tolerance = 5e-3 if "ground" in plant_file else 1e-3
    for step in result.steps:
        if step.final_position_error is not None:
            assert step.final_position_error < tolerance, step
            assert step.final_rotation_error < 1e-2, step
    exported = export_csv(result.recording, tmp_path / "run.csv")
    with open(tmp_path / "run.csv", newline="") as f:
        header = next(csv.reader(f))
    n = ARMS[arm]
    assert f"q_{n}" in header and f"q_{n + 1}" not in header and f"tau_{n}" in header
    assert exported.rows > 100 and not exported.gaps
