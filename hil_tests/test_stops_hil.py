"""Stops on the separate-process stack (issue 28): `spacearm sim` and the daemon on the
loopback hub, the simulator at SCHED_FIFO 50; the operator's `spacearm stop` with the
real-time daemon (20 ms, FIFO 50) as the README runs it, the other paths with the lockstep
daemon (deterministic: a loaded machine cannot stop it for late data before the fault is
injected). Each stop path is triggered while a joint moves
at its full speed (0.1745 rad/s on the ORU test bed), judged from the daemon's recording:
speed from differences of recorded positions never above the pre-stop speed nor the limit
(+5 % of the limit), monotonic deceleration, distance and time to rest within their bounds
(controller/daemon/stop_metrics.py), and the drives and brakes as the stop's category says
(controller/daemon/stops.py). Timings are printed; the behaviour is asserted."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from hil_tests.conftest import ROOT, child_env
from hil_tests.faults import NOMINAL_PLANT, Stack, start_stack, wait_for, wait_safe
from hil_tests.harness import free_port
from spacearm.base.runtime.priority import use_fifo, use_normal
from spacearm.console.client import ApiClient
from spacearm.controller.daemon.stop_metrics import recorded_stop, stop_figures
from spacearm.controller.recording.mcap_reader import read_recording

pytestmark = [pytest.mark.hil, pytest.mark.multiprocess]

ARM_A_MAX = 0.3490658503988659      # rad/s^2, every joint of configs/arm/oru_testbed_6dof.toml
ARM_V_MAX = 0.17453292519943295


@pytest.fixture(scope="module")
def stack(loopback_hub, tmp_path_factory):
    s = start_stack(loopback_hub, tmp_path_factory.mktemp("stops"))
    yield s
    s.close()


@pytest.fixture(scope="module")
def lockstep_stack(loopback_hub, tmp_path_factory):
    workdir = tmp_path_factory.mktemp("stops_lockstep")
    channel = f"stops-{os.getpid()}-{time.monotonic_ns()}"
    s = Stack(loopback_hub.spec(channel), channel, f"tcp:127.0.0.1:{free_port()}", workdir, NOMINAL_PLANT)
    try:
        s.start_sim()
        s.rig
        s.daemon = s._spawn(["daemon", "--clock", "lockstep", "--api", s.api, "--record-dir", str(workdir / "runs")],
                            "daemon", "spacearm daemon:", 60)
        s.client = ApiClient(s.api, timeout=10.0)
        s.lease = s.client.call("control.take", holder="stops-suite")["lease"]
        yield s
    finally:
        s.close()


def _full_speed_jog(stack, joint: int, delta: float = 0.6) -> float:
    """Enable, start a jog of `joint` (1-based) away from its nearer limit, and wait until it has
    run at its limit for 0.2 s (this test's client polls status: the jog's keep-alive). Returns
    the controller time the jog started at: the daemon's one recording is judged from there."""
    status = stack.status()
    if status["state"] == "stopped":
        wait_for(lambda: not any(j["enabled"] for j in stack.status()["joints"]), 5, "stop over")
        stack.recover()
    stack.enable()
    status = stack.status()
    started, q = status["time"], status["joints"][joint - 1]["q"]
    stack.call("jog", joint=joint, delta=-delta if q > 0 else delta)
    fast_since = None
    deadline = time.monotonic() + 10
    while True:
        s = stack.status()
        assert s["state"] == "enabled", s["stop_reason"]
        if abs(s["joints"][joint - 1]["dq"]) > 0.99 * ARM_V_MAX:
            fast_since = fast_since or time.monotonic()
            if time.monotonic() - fast_since > 0.2:
                return started
        else:
            fast_since = None
        assert time.monotonic() < deadline, "the jog never reached full speed"
        time.sleep(0.02)


def _judge(stack, code: str, joint: int, since: float, timeout: float = 5.0) -> list:
    safe = wait_safe(stack, time.monotonic(), code, timeout=timeout)
    assert safe.status["stop"]["code"] == code, safe.status["stop"]
    assert not any(j["enabled"] for j in safe.status["joints"])
    # the recording as far as it reached the disk (the recorder flushes about once a second);
    # closing it for each test cost more than the client's 10 s on a loaded machine
    path, end = safe.status["recording"]["path"], safe.status["time"]
    wait_for(lambda: _recorded_until(path) >= end, 2 * timeout, "the stop in the recording")
    figures = _figures(path, since)
    f = figures[joint - 1]
    late = safe.status["network"].get("late_cycles", 0)
    print(f"\n{code} joint {joint}: v {f.v_stop:.4f} rad/s, peak/limit {f.peak / f.limit:.3f}, distance "
          f"{1e3 * f.distance:.1f} mrad (bound {1e3 * f.distance_bound:.1f}), time {f.time_to_rest:.3f} s "
          f"(bound {f.time_bound:.3f}); stop shown after {safe.to_stop:.3f} s, late cycles {late}")
    assert f.v_stop > 0.95 * ARM_V_MAX, f
    problems = [p for g in figures for p in g.problems()]
    assert not problems, problems
    return figures


def _recorded_until(path) -> float:
    cycles = read_recording(path, {"/cycle"}).topic("/cycle")
    return cycles[-1].data["t"] if cycles else -1.0


def _figures(path, since: float = 0.0) -> list:
    rec = read_recording(path)
    t, q, t_stop = recorded_stop([c.data for c in rec.topic("/cycle") if c.data["t"] >= since],
                                 [e.data for e in rec.topic("/events") if e.data["t"] >= since],
                                 0.02)
    return stop_figures(t, q, t_stop, np.full(6, ARM_V_MAX), np.full(6, ARM_A_MAX), 0.02)


@pytest.fixture
def console_priority():
    """The jogging console (this test) at SCHED_FIFO 20, as `spacearm stop` asks for: on a loaded
    machine a normal-priority console misses its jog's 1 s keep-alive and the watchdog stops
    the arm before the stop under test."""
    use_fifo(20)
    yield
    use_normal()


@pytest.mark.parametrize("joint", [1, 4])
def test_spacearm_stop_mid_jog(stack, joint, console_priority):
    """`spacearm stop` from a second console (no lease) while a joint jogs at full speed (a
    1.5 rad jog: 8.6 s, longer than `spacearm stop` takes to start on a loaded machine)."""
    since = _full_speed_jog(stack, joint, 1.5)
    stopper = subprocess.Popen([sys.executable, "-m", "spacearm.console.main", "stop", "--api", stack.api],
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=ROOT, env=child_env())
    while stopper.poll() is None:     # the jogging console stays alive meanwhile (its keep-alive)
        stack.status()
        time.sleep(0.05)
    assert stopper.returncode == 0, stopper.stdout.read()
    _judge(stack, "operator_stop", joint, since)


@pytest.mark.under_load
def test_spacearm_stop_mid_jog_beside_two_cpu_bound_processes(stack, console_priority):
    since = _full_speed_jog(stack, 1, 1.5)
    stack.client.call("stop")
    _judge(stack, "operator_stop", 1, since)


def test_drive_fault_mid_jog_stops_on_the_drives_ramps(lockstep_stack):
    stack = lockstep_stack
    since = _full_speed_jog(stack, 4, 1.5)
    stack.rig.raise_fault("joint_4", 0x5441)
    _judge(stack, "emcy", 4, since)
    assert stack.status()["joints"][3]["fault"]


def test_lost_node_mid_jog_stops_on_the_drives_quick_stop(lockstep_stack):
    """The F/T sensor stops answering SYNC (its process data lost; in lockstep a node still
    sending TPDOs counts as alive, so a stopped heartbeat alone is no loss there)."""
    stack = lockstep_stack
    since = _full_speed_jog(stack, 1, 1.5)
    stack.rig.ignore_sync("ft_sensor", True)
    try:
        # the jogging console stays alive (its keep-alive) until the loss is detected
        wait_for(lambda: stack.status()["state"] == "stopped", 10, "process data loss detected", poll=0.05)
        # every cycle now waits lockstep_timeout (0.5 s) for the silent node: 2 cycles a second
        _judge(stack, "pdo_missing", 1, since, timeout=40.0)
    finally:
        stack.rig.ignore_sync("ft_sensor", False)
        time.sleep(0.5)


def test_sigterm_mid_jog_stops_the_arm_before_the_daemon_ends(lockstep_stack):
    """Last in the module: the daemon ends. Its recording is read after it closed it."""
    stack = lockstep_stack
    since = _full_speed_jog(stack, 4, 1.5)
    path = stack.status()["recording"]["path"]
    os.killpg(stack.daemon.pid, signal.SIGTERM)
    stack.daemon.wait(15)
    stop = [e.data for e in read_recording(path).topic("/events") if e.data["kind"] == "protective_stop"][-1]
    assert stop["code"] == "shutdown"
    figures = _figures(path, since)
    print("\nshutdown joint 4:", json.dumps({k: round(float(v), 4) for k, v in figures[3].row().items()}))
    problems = [p for g in figures for p in g.problems()]
    assert not problems, problems
