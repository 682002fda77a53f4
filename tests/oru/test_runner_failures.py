"""The task runner inside the controller core, without plant or bus: the Table 1 structure,
and a failure injected at every one of the 26 subtasks ends in a protective stop (drives
disabled, reason kept). The measurement is scripted: the arm follows its command exactly and
the F/T sensor reads the end effector's weight."""
from __future__ import annotations

import time

import numpy as np
import pytest

from spacearm.base.config.arm import load_arm_config
from spacearm.base.config.scene import load_scene
from spacearm.controller.daemon.core import ControllerCore
from spacearm.controller.modes import HoldMode
from spacearm.controller.cycle import DeviceEvent, Measurement
from spacearm.controller.daemon.supervision import SupervisionLimits, Supervisor
from spacearm.controller.impedance.config import load_impedance
from spacearm.base.kinematics import KinematicData, KinematicModel, fk
from spacearm.controller.oru.config import load_changeout
from spacearm.controller.oru.flow import FlowContext
from spacearm.controller.oru.runner import OruTaskRunner
from spacearm.controller.oru.steps import ContactStep, EndEffectorStep, LatchStep, ModeStep
from spacearm.controller.planning.motion_planner import MotionPlanner

ARM = load_arm_config("configs/arm/oru_testbed_6dof.toml")
MODEL = KinematicModel.from_config(ARM)
READY = np.array(ARM.postures["ready"])


def make_runner() -> OruTaskRunner:
    ctx = FlowContext(MODEL, MotionPlanner(MODEL, 0.02, ARM.cartesian), load_scene(), load_changeout(),
                      load_impedance(), {}, READY.copy())
    return OruTaskRunner(ctx)


class Rig:
    def __init__(self, runner: OruTaskRunner):
        self.runner = runner
        self.core = ControllerCore(Supervisor(SupervisionLimits(np.array(MODEL.q_min), np.array(MODEL.q_max),
                                                                np.array(MODEL.v_max)), list(MODEL.joint_names)),
                                   list(MODEL.joint_names), 0.02)
        self.core.state = "enabled"
        self.core.mode = HoldMode(READY.copy())
        self.q = READY.copy()
        self.t = 0.0
        self.data = KinematicData(MODEL)
        self.ee_state = "open"
        self.gravity = runner.ctx.gravity()
        m = self.measurement()
        self.core.start_planned(0.0, m, runner, None)

    def measurement(self, extra=np.zeros(6), ee=None, events=()) -> Measurement:
        R = fk(MODEL, self.data, self.q)[:3, :3]
        n = MODEL.nq
        return Measurement(self.t, 0, self.q.copy(), np.zeros(n), np.zeros(n), np.ones(n, bool), np.zeros(n, bool),
                           self.gravity.wrench(R) + extra, end_effector=ee or self.ee_state, events=events)

    def cycle(self, **inject):
        command = self.core.update(self.measurement(**inject))
        if command.enable:
            self.q = command.q.copy()
        self.t += 0.02
        return command


def test_four_stages_follow_table_1():
    runner = make_runner()
    assert len(runner.steps) == 26
    assert [(s.stage + 1, s.number) for s in runner.steps] == \
        [(1, n) for n in range(1, 7)] + [(2, n) for n in range(7, 14)] + \
        [(3, n) for n in range(1, 7)] + [(4, n) for n in range(7, 14)]
    algorithms = {s.number: s.algorithm for s in runner.steps}
    assert algorithms[1] == algorithms[7] == algorithms[13] == "open loop path planning"
    assert all(algorithms[n] == "impedance control" for n in (3, 6, 9, 12))
    assert "fallback" in algorithms[2] and "fallback" in algorithms[8]   # no approach mode registered


@pytest.mark.parametrize("index", range(26))
def test_failure_at_every_subtask_ends_in_a_protective_stop(index):
    runner = make_runner()
    runner.index = index
    step = runner.steps[index]
    if step.stage % 2 == 1 and step.number < 11 or step.number == 6:
        runner.ctx.holding = "old_oru"
    if step.number == 13:
        runner.ctx.q_initial = np.array(ARM.postures["home"])   # a return path of some length
    rig = Rig(runner)
    if isinstance(step, EndEffectorStep):
        rig.ee_state = "open" if step.expect == "locked" else "locked"   # still on its way
    for _ in range(15):                      # begin the step, tare, a few normal cycles
        rig.cycle()
        if isinstance(step, ModeStep) and step.background:
            time.sleep(0.002)                # let the planning thread deliver
        assert rig.core.state == "enabled", rig.core.stop_reason
    assert runner.index == index and runner.state == "running"
    if isinstance(step, ContactStep):
        inject, code = {"extra": np.array([60.0, 0, 0, 0, 0, 0])}, "contact_force_limit"
    elif isinstance(step, EndEffectorStep):
        inject, code = {"ee": "fault"}, "end_effector_fault"
    else:
        assert isinstance(step, (LatchStep, ModeStep))
        inject, code = {"events": (DeviceEvent("joint_3", "heartbeat_lost", "silent"),)}, None
    for _ in range(3):
        command = rig.cycle(**inject)
        if rig.core.state == "stopped":
            break
    assert rig.core.state == "stopped"
    assert not command.enable                # quick stop, brakes
    if code is not None:
        assert rig.core.stop_reason.code == code
        assert f"subtask {step.number}" in rig.core.stop_reason.message
        assert runner.state == "failed"
