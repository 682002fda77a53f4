"""Stops judged by what the joints did (issue 28): a joint at full speed, stopped mid-motion,
must never speed up, must decelerate monotonically and come to rest within v^2/2a + one
cycle's travel (+10 %) and v/a + 2 cycles, judged from the recorded measured positions; and
end in the drive and brake state its category names (controller/daemon/stops.py)."""
from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

from spacearm.controller.cycle import Finding, FindingCode
from spacearm.controller.daemon.stop_metrics import recorded_stop, stop_figures
from spacearm.controller.daemon.stops import QUICK_STOP_ACK_CYCLES, stops_table
from tests.daemon.stop_run import stepped_daemon

README = Path(__file__).resolve().parents[2] / "README.md"


def _judge(run, joints=None, one_path=False):
    _, _, events, cycles = run.recording()
    period = run.daemon.options.period
    t, q, t_stop = recorded_stop([c.data for c in cycles], events, period)
    a_max = np.array([j.limits.acceleration for j in run.daemon.arm.joints])
    figures = stop_figures(t, q, t_stop, np.array(run.daemon.model.v_max), a_max, period, joints, one_path)
    return figures, events, cycles


def _assert_inside_bounds(figures, moving_joint):
    assert figures[moving_joint].v_stop > 0.98 * figures[moving_joint].limit, figures[moving_joint]
    problems = [p for f in figures for p in f.problems()]
    assert not problems, problems


def _assert_off_and_braked(run):
    m = run.core.last_measurement
    assert not m.joints_enabled.any() and all(run.brakes()), (m.joints_enabled, run.brakes())


@pytest.mark.parametrize("joint", [0, 3])
def test_operator_stop_at_full_speed_never_speeds_the_joint_up(tmp_path, joint):
    """The defect of issue 28: the joint sped up to 1.63x its limit after the stop."""
    with stepped_daemon(tmp_path) as run:
        run.enable()
        run.jog_at_full_speed(joint)
        run.stop_and_settle()
        _assert_off_and_braked(run)
        figures, events, _ = _judge(run)
    assert events[[e["kind"] for e in events].index("protective_stop")]["code"] == "operator_stop"
    print(figures[joint].row())
    _assert_inside_bounds(figures, joint)


def test_operator_stop_at_4_ms_cycle(tmp_path):
    with stepped_daemon(tmp_path, period=0.004) as run:
        run.enable()
        run.jog_at_full_speed(0, delta=0.4)
        run.stop_and_settle()
        _assert_off_and_braked(run)
        figures, _, _ = _judge(run)
    print(figures[0].row())
    _assert_inside_bounds(figures, 0)


def test_all_joints_stop_on_one_path(tmp_path):
    """A joint move of every joint at once, stopped mid-way: the joints keep their speed
    ratios while stopping (the commanded stop is one path) and each is inside its bounds."""
    with stepped_daemon(tmp_path) as run:
        run.enable()
        q0 = run.m.q.copy()
        run.start("move_joints", run.daemon.planner.joint_move(q0, q0 + np.array([0.5, 0.4, -0.3, 0.5, 0.2, -0.45])))
        run.cycles(120)                      # cruising
        run.stop_and_settle()
        figures, events, cycles = _judge(run, one_path=True)
    for f in figures:
        print(f.row())
    problems = [p for f in figures for p in f.problems()]
    assert not problems, problems
    t_stop = next(e["t"] for e in events if e["kind"] == "protective_stop")
    t_rest = next(e["t"] for e in events if e["kind"] == "stop")      # the planner's stop is over
    commanded = np.array([c.data["q_cmd"] for c in cycles if t_stop <= c.data["t"] < t_rest])
    steps = np.diff(commanded, axis=0)
    moving = steps[np.abs(steps[:, 0]) > 1e-6]
    assert len(moving) > 15
    ratios = moving / moving[:, :1]
    np.testing.assert_allclose(ratios, np.broadcast_to(ratios[0], ratios.shape), atol=1e-6)


def test_drive_quick_stop_on_a_lost_node(tmp_path):
    """An EMCY from the F/T sensor: the drives stop themselves (605Ah = 2 on 6085h = the arm's
    acceleration, from the joint's measured speed), then power off and brake."""
    with stepped_daemon(tmp_path) as run:
        run.enable()
        run.jog_at_full_speed(0)
        run.sim.node("ft_sensor").emcy(0x5000)
        run.cycles(int(1.5 / 0.02))
        _assert_off_and_braked(run)
        figures, events, _ = _judge(run)
    assert next(e for e in events if e["kind"] == "protective_stop")["code"] == "emcy"
    _assert_inside_bounds(figures, 0)


def test_drive_fault_mid_motion_stops_on_its_fault_reaction(tmp_path):
    with stepped_daemon(tmp_path) as run:
        run.enable()
        run.jog_at_full_speed(3)
        run.sim.node("joint_4").inject_fault(0x5441)
        run.cycles(int(1.5 / 0.02))
        m = run.core.last_measurement
        assert m.joints_faulted[3] and not m.joints_enabled.any() and all(run.brakes())
        figures, events, _ = _judge(run)
    assert next(e for e in events if e["kind"] == "protective_stop")["code"] in ("emcy", "fault")
    _assert_inside_bounds(figures, 3)


def test_a_drive_that_ignores_quick_stop_is_powered_off_by_the_controller(tmp_path):
    with stepped_daemon(tmp_path) as run:
        run.enable()
        run.sim.node("joint_1").faults.ignore_quick_stop = True
        run.jog_at_full_speed(0)
        run.stop_and_settle()
        _assert_off_and_braked(run)
        figures, events, _ = _judge(run)
    at_rest = next(e for e in events if e["kind"] == "stop")
    escalated = next(e for e in events if e["kind"] == "stop_escalated")
    assert escalated["code"] == "quick_stop_ignored" and escalated["joint"] == "shoulder_yaw"
    cycles = round((escalated["t"] - at_rest["t"]) / 0.02)
    print(f"powered off {cycles} cycles after the quick-stop request")
    assert cycles <= QUICK_STOP_ACK_CYCLES + 1
    _assert_inside_bounds(figures, 0)


def test_stop_while_stopping_changes_nothing(tmp_path):
    with stepped_daemon(tmp_path) as run:
        run.enable()
        run.jog_at_full_speed(0)
        run.apply(run.core.cmd_stop)
        run.cycles(5)
        run.apply(run.core.cmd_stop)                  # the operator presses again
        run.core.protective_stop(run.m.time, Finding(FindingCode.COMMAND_WATCHDOG, "console gone"))
        refused = _refused(lambda: run.apply(run.core.cmd_reset))
        run.cycles(70)
        _assert_off_and_braked(run)
        figures, events, _ = _judge(run)
    assert refused is not None and refused.code == "busy"
    assert [e["kind"] for e in events].count("protective_stop") == 1
    _assert_inside_bounds(figures, 0)


def test_stop_with_no_drive_enabled_and_from_a_console_without_the_lease(tmp_path):
    with stepped_daemon(tmp_path) as run:
        q0 = run.m.q.copy()
        box = {}
        caller = threading.Thread(target=lambda: box.setdefault("r", run.daemon.handlers.handle(None, "stop", {})))
        caller.start()                          # no lease: stop needs none
        while caller.is_alive():
            run.cycles()
        assert box["r"] == "stopped"
        run.cycles(20)
        assert np.max(np.abs(run.m.q - q0)) < 1e-6 and all(run.brakes())
        assert run.apply(run.core.cmd_reset) == "disabled"
        run.enable()                            # and back to work: no jump at enable
        run.cycles(25)
        assert np.max(np.abs(run.m.q - q0)) < 5e-4


def test_sigterm_stops_a_moving_arm_before_powering_off(tmp_path):
    with stepped_daemon(tmp_path) as run:
        run.enable()
        run.jog_at_full_speed(3)
        run.daemon.request_stop()             # what SIGINT/SIGTERM do
        run.daemon.run()
        _assert_off_and_braked(run)
        figures, events, _ = _judge(run)
    assert next(e for e in events if e["kind"] == "protective_stop")["code"] == "shutdown"
    _assert_inside_bounds(figures, 3)


def test_new_motion_after_a_stop_starts_without_a_step(tmp_path):
    """Reset and enable after a stop, then a jog: the commanded position never steps by more
    than the motion's own per-cycle travel, and the joints do not move at enable."""
    with stepped_daemon(tmp_path) as run:
        run.enable()
        run.jog_at_full_speed(0)
        run.stop_and_settle()
        assert run.apply(run.core.cmd_reset) == "disabled"
        rest = run.m.q.copy()
        run.enable()
        run.cycles(10)
        moved_at_enable = np.max(np.abs(run.m.q - rest))
        run.start("jog", run.daemon.planner.jog(run.apply(run.core.motion_start), 0, -0.05))
        run.cycles(30)
        _, _, _, cycles = run.recording()
    q_cmd = np.array([c.data["q_cmd"] for c in cycles])
    last = [i for i, c in enumerate(cycles) if c.data["state"] == "stopped"][-1]
    after = q_cmd[last:]
    print(f"moved at enable {1e3 * moved_at_enable:.3f} mrad, largest command step "
          f"{1e3 * np.max(np.abs(np.diff(after, axis=0))):.3f} mrad")
    assert moved_at_enable < 5e-4
    assert np.max(np.abs(np.diff(after, axis=0))) <= 0.1745 * 0.02 * 1.01


def test_readme_carries_the_stop_table():
    assert stops_table() in README.read_text()


def _refused(call):
    from spacearm.controller.daemon.core import CommandRefused
    try:
        call()
    except CommandRefused as exc:
        return exc
    return None


def test_bringup_sets_each_drives_stop_ramps_from_the_arm_file(tmp_path):
    """Read back from the drives: 6085h = the arm file's acceleration limit, 605Ah = 2 (ramp,
    then power off and brake), 605Eh = 2 (a fault stops on the same ramp)."""
    from spacearm.base.canopen import od
    with stepped_daemon(tmp_path) as run:
        net = run.daemon.hardware.network
        for joint, driver in zip(run.daemon.arm.joints, net.joints):
            ramp = net.sdo_read(driver.name, od.QUICK_STOP_DECELERATION, 0) / driver.k
            assert ramp == pytest.approx(joint.limits.acceleration, rel=1e-6)
            assert net.sdo_read(driver.name, od.QUICK_STOP_OPTION, 0) == 2
            assert net.sdo_read(driver.name, od.FAULT_REACTION_OPTION, 0) == 2


def test_a_cartesian_move_stops_on_its_line(tmp_path):
    """A straight tool move from `ready`, stopped mid-way: every joint inside its bounds (on one
    path) and the measured tool position leaves the move's line by less than 0.5 mm."""
    from spacearm.base.kinematics.forward import fk
    from spacearm.base.kinematics.model import KinematicData
    with stepped_daemon(tmp_path) as run:
        run.enable()
        q0 = run.m.q.copy()
        run.start("move_joints", run.daemon.planner.joint_move(q0, np.array(run.daemon.arm.postures["ready"])))
        run.until(lambda s: s.mode == "hold", 2000)
        start = run.m.q.copy()
        run.start("move_pose", run.daemon.planner.pose_move(start, np.array([0.0, 0.0, 0.15]), np.zeros(3), "tool"))
        run.cycles(60)
        run.stop_and_settle()
        figures, events, cycles = _judge(run, one_path=True)
    problems = [p for f in figures for p in f.problems()]
    assert not problems, problems
    model, data = run.daemon.model, KinematicData(run.daemon.model)
    p0 = fk(model, data, start)[:3, 3].copy()
    t_stop = next(e["t"] for e in events if e["kind"] == "protective_stop")
    tool = np.array([fk(model, data, np.array(c.data["q"]))[:3, 3] for c in cycles if c.data["t"] >= t_stop])
    direction = tool[-1] - p0
    direction /= np.linalg.norm(direction)
    off_line = np.linalg.norm(np.cross(tool - p0, direction), axis=1)
    print(f"tool off the line while stopping: {1e3 * off_line.max():.3f} mm, stopped "
          f"{1e3 * np.linalg.norm(tool[-1] - tool[0]):.1f} mm after the stop")
    assert off_line.max() < 0.5e-3


def test_disable_mid_motion_stops_first_then_powers_off(tmp_path):
    with stepped_daemon(tmp_path) as run:
        run.enable()
        run.jog_at_full_speed(3)
        assert run.apply(run.core.cmd_disable) == "enabled"          # still stopping
        refused = _refused(lambda: run.apply(run.core.motion_start))
        run.cycles(int(1.5 / 0.02))
        assert run.core.state == "disabled" and run.core.stop_reason is None
        _assert_off_and_braked(run)
        t, q, events, cycles = run.recording()
    assert refused is not None and refused.code == "busy"
    k = next(i for i, c in enumerate(cycles) if "disabling" in " ".join(
        e["message"] for e in events if e["t"] == c.data["t"]))
    a_max = np.array([j.limits.acceleration for j in run.daemon.arm.joints])
    figures = stop_figures(t, q, t[k], np.array(run.daemon.model.v_max), a_max, 0.02)
    _assert_inside_bounds(figures, 3)
