"""The main job (`spacearm demo`) in one process: nodes, the camera rendering into a shared-
memory ring, the daemon with its vision worker, lockstep, on the demo plant with hidden arm,
thermal and store errors (configs/plant/oru_cell_errors.toml). With the camera every approach
ends within the paper's 1 mm / 0.3 deg of the truth (the simulator's) and the ORUs seat; without
it the same errors jam the first insertion."""
from __future__ import annotations

import math
import time

import pytest

pytestmark = [pytest.mark.hil, pytest.mark.slow]
PLANT = "configs/plant/oru_cell_errors.toml"


def _embedded(vision: bool):
    """The main job's stack in one process (spacearm demo): nodes, camera ring, daemon, lockstep."""
    import threading
    from spacearm.controller.daemon.daemon import Daemon, DaemonOptions
    from spacearm.firmware_sim.runner import start_simulator
    from spacearm.offline.scenarios.changeout import start_camera
    from hil_tests.camera_stack import BUS_CONFIG
    bus = f"virtual:oru-cam-{time.monotonic_ns()}"
    sim = start_simulator(bus, BUS_CONFIG, PLANT, time_base="sync")
    ring, camera = start_camera(sim) if vision else (None, None)
    daemon = Daemon(DaemonOptions(bus=bus, bus_config=BUS_CONFIG, clock="lockstep", api=None, record_dir=None,
                                  camera=camera))
    daemon.start()
    thread = threading.Thread(target=daemon.run, daemon=True)
    thread.start()

    def close():
        daemon.request_stop()
        thread.join(5)
        daemon.shutdown()
        sim.stop()
        if ring is not None:
            ring.close()
    return sim, daemon, close


def test_main_job_approaches_end_within_the_papers_tolerance_of_the_truth():
    from spacearm.offline.scenarios.changeout import run_changeout
    sim, daemon, close = _embedded(vision=True)
    try:
        result = run_changeout(daemon, lambda name, f: None, plant=sim.plant, stages=[1, 2])
    finally:
        close()
    assert [s.number for s in result.stages] == [1, 2]
    for s in result.stages:
        assert s.approach == "closed loop (vision)" and s.approach_attempts == 1
        position, angle = s.approach_error             # simulator truth at the handover to contact
        assert position <= 1.0e-3 and angle <= math.radians(0.3), (s.number, position, angle)
        assert s.frames >= 3 and s.detected / s.frames >= 0.8
        assert s.peak_force < 40.0
    assert all(error[0] < 1.5e-3 for error in result.seat_errors.values())


def test_without_the_camera_the_demo_plants_errors_jam_the_insertion():
    from spacearm.offline.scenarios.changeout import ChangeoutFailed, run_changeout
    sim, daemon, close = _embedded(vision=False)
    try:
        with pytest.raises(ChangeoutFailed, match="inserts the ORU"):
            run_changeout(daemon, lambda name, f: None, plant=sim.plant, stages=[1, 2])
        assert daemon.core.stop_reason.code == "jammed"
    finally:
        close()
