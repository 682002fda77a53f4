"""The ORU paper's stiffness experiment (Section 5.2) over the CAN bus: impedance on x with
K = 1 N/mm and B = 50 N s/m, position control on the other axes, an external force ramped to
5 N along x: the tool gives 5 mm, y and z stay within 0.5 mm (plant truth, the laser tracker)."""
from __future__ import annotations

import numpy as np
import pytest

from spacearm.controller.impedance.gravity import GravityModel
from spacearm.offline.contact.trials import force_ramp, stiffness_task
from hil_tests.oru_stack import OruStack

pytestmark = pytest.mark.hil


def test_stiffness_experiment_over_the_bus():
    stack = OruStack()
    try:
        stack.ready()
        daemon, core = stack.daemon, stack.daemon.core
        ee = daemon.oru.changeout.end_effector
        task = stiffness_task(GravityModel(ee.mass, np.asarray(ee.centroid)), ee.sensor_offset, duration=10.0)
        start = {}

        def begin(t, m):
            mode = daemon.mode_factories["impedance"](core.motion_start(t, m), task)
            start["pose"] = stack.sim.plant.tool_pose()[:3, 3].copy()
            # Force on after the mode's tare; the plant's clock runs with the SYNCs.
            t_on = stack.sim.plant.time + (task.tare_cycles + 2) * daemon.options.period
            stack.world.applied_profile = lambda now: np.array([force_ramp(now - t_on), 0, 0, 0, 0, 0])
            return core.start_planned(t, m, mode, None)

        motion = daemon.handlers._in_cycle(begin)["motion"]
        stack.wait(lambda: daemon.snapshot.motions_finished >= motion or core.state == "stopped", 120)
        assert core.state == "enabled", core.stop_reason
        moved = stack.sim.plant.tool_pose()[:3, 3] - start["pose"]
        assert stack.world.applied_wrench[0] == pytest.approx(5.0)
        assert abs(moved[0] - 0.005) <= 0.2e-3, moved
        assert np.all(np.abs(moved[1:]) < 0.5e-3), moved
    finally:
        stack.close()
