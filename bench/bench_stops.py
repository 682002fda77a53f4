#!/usr/bin/env python3
"""Stop benchmark (issue 28): every stop path, triggered while the ORU test bed's joints move at
full speed (0.1745 rad/s), judged from the daemon's recording.

    .venv/bin/python bench/bench_stops.py

Daemon and simulator in this process on the virtual bus, lockstep clock driven cycle by cycle
(tests/daemon/stop_run.py), so each stop happens at a known cycle and the physics does not
depend on this machine's load; the separate-process, real-time version of the main paths is
hil_tests/test_stops_hil.py. Per path: the pre-stop speed, the peak speed after the stop over
the limit, stopping distance and time to rest against their bounds (v^2/2a + vT, +10 %;
v/a + 2T), the worst joint's figures when several move, the state reached (drives, brakes,
stop code), and the wall time with load and CPU steal. The figures are physical (from recorded
positions over SYNC time), not timings: load changes none of them, and the wall time is
printed only to show what the run cost.
"""
from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.chdir(ROOT)

from hil_tests.harness import CpuSteal  # noqa: E402
from spacearm.controller.cycle import Finding, FindingCode  # noqa: E402
from spacearm.controller.daemon.stop_metrics import recorded_stop, stop_figures  # noqa: E402
from tests.daemon.stop_run import stepped_daemon  # noqa: E402

ALL_JOINTS = np.array([0.5, 0.4, -0.3, 0.5, 0.2, -0.45])


def operator_stop(run):
    run.stop_and_settle()


def node_lost(run):
    run.sim.node("ft_sensor").emcy(0x5000)
    run.cycles(int(1.5 / run.daemon.options.period))


def drive_fault(run):
    run.sim.node(f"joint_{run.joint + 1}").inject_fault(0x5441)
    run.cycles(int(1.5 / run.daemon.options.period))


def ignores_quick_stop(run):
    run.sim.node(f"joint_{run.joint + 1}").faults.ignore_quick_stop = True
    run.stop_and_settle()


def stop_while_stopping(run):
    run.apply(run.core.cmd_stop)
    run.cycles(5)
    run.apply(run.core.cmd_stop)
    run.core.protective_stop(run.m.time, Finding(FindingCode.COMMAND_WATCHDOG, "console gone"))
    run.cycles(int(1.5 / run.daemon.options.period))


def disable_mid_motion(run):
    run.apply(run.core.cmd_disable)
    run.cycles(int(1.5 / run.daemon.options.period))


def sigterm(run):
    run.daemon.request_stop()
    run.daemon.run()


# name, trigger, moving joint (None: all joints on one joint move), cycle period
PATHS = [
    ("operator stop, joint 1", operator_stop, 0, 0.02),
    ("operator stop, joint 4", operator_stop, 3, 0.02),
    ("operator stop, all joints", operator_stop, None, 0.02),
    ("operator stop, joint 1, 4 ms", operator_stop, 0, 0.004),
    ("node lost (EMCY): drives' quick stop", node_lost, 0, 0.02),
    ("drive fault: its fault reaction", drive_fault, 3, 0.02),
    ("drive ignores quick stop", ignores_quick_stop, 0, 0.02),
    ("stop while stopping", stop_while_stopping, 0, 0.02),
    ("SIGTERM", sigterm, 3, 0.02),
    ("disable during a motion", disable_mid_motion, 3, 0.02),
]


def run_path(trigger, joint, period, folder: Path) -> dict:
    folder.mkdir(parents=True)
    with stepped_daemon(folder, period=period) as run:
        run.joint = joint
        run.enable()
        if joint is None:
            q0 = run.m.q.copy()
            run.start("move_joints", run.daemon.planner.joint_move(q0, q0 + ALL_JOINTS))
            run.cycles(int(2.4 / period))
        else:
            run.jog_at_full_speed(joint, 0.6 if period == 0.02 else 0.4)
        trigger(run)
        m = run.core.last_measurement
        drives = "off" if not (m.joints_powered if m.joints_powered is not None else m.joints_enabled).any() else "ON"
        brakes = "on" if all(run.brakes()) else "OFF"
        faulted = [int(i) + 1 for i in np.flatnonzero(m.joints_faulted)]
        _, _, events, cycles = run.recording()
        arm = run.daemon.arm
    marked = events if any(e["kind"] == "protective_stop" for e in events) else [
        {**e, "kind": "protective_stop"} for e in events if "disabling" in e["message"]]   # disable: no stop reason
    t, q, t_stop = recorded_stop([c.data for c in cycles], marked, period)
    a_max = np.array([j.limits.acceleration for j in arm.joints])
    v_max = np.array([j.limits.velocity for j in arm.joints])
    figures = stop_figures(t, q, t_stop, v_max, a_max, period, one_path=joint is None)
    judged = figures if joint is None else [figures[joint]]
    worst = max(judged, key=lambda f: f.distance / f.distance_bound)
    stop = next((e for e in events if e["kind"] == "protective_stop"), {"code": "(disable: no stop)"})
    escalated = [e["code"] for e in events if e["kind"] == "stop_escalated"]
    state = f"drives {drives}, brakes {brakes}" + (f", fault: joint {', '.join(map(str, faulted))}" if faulted else "")
    return {"figure": worst, "problems": [p for f in figures for p in f.problems()], "code": stop["code"],
            "escalated": escalated, "state": state}


def main() -> int:
    steal = CpuSteal()
    print(f"stop benchmark: ORU test bed (configs/arm/oru_testbed_6dof.toml, limit 0.1745 rad/s, "
          f"0.349 rad/s^2), lockstep, load avg {os.getloadavg()[0]:.1f} at start")
    header = (f"{'stop path':38} {'code':37} {'jnt':>3} {'v stop':>7} {'peak/lim':>8} {'dist mrad':>10} "
              f"{'bound':>6} {'time s':>7} {'bound':>6} {'state reached':40} {'ok':3} {'wall s':>6} {'load':>5} {'steal':>6}")
    print(header)
    print("-" * len(header))
    failures = 0
    with tempfile.TemporaryDirectory() as tmp:
        for k, (name, trigger, joint, period) in enumerate(PATHS):
            started = time.monotonic()
            r = run_path(trigger, joint, period, Path(tmp) / str(k))
            wall = time.monotonic() - started
            f = r["figure"]
            ok = not r["problems"]
            failures += not ok
            code = r["code"] + (f" -> {r['escalated'][0]}" if r["escalated"] else "")
            print(f"{name:38} {code:37} {f.joint + 1:>3} {f.v_stop:7.4f} {f.peak / f.limit:8.3f} "
                  f"{1e3 * f.distance:10.1f} {1e3 * f.distance_bound:6.1f} {f.time_to_rest:7.3f} {f.time_bound:6.3f} "
                  f"{r['state']:40} {'yes' if ok else 'NO':3} {wall:6.1f} {os.getloadavg()[0]:5.1f} "
                  f"{100 * steal.fraction():5.1f}%")
            for problem in r["problems"]:
                print(f"    outside its bounds: {problem}")
    print(f"\n{len(PATHS) - failures}/{len(PATHS)} stop paths inside every bound (peak <= min(v, limit) + 5 % of the "
          f"limit, monotonic, distance <= (v^2/2a + vT) x 1.1, time <= v/a + 2T; all joints: each joint's a from the "
          f"common stop time)")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
