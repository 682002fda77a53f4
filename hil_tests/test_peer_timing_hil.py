"""A starved simulator or hub says so itself: with `spacearm hub`, `spacearm sim` and the daemon
in separate processes, freezing the simulator (or the hub) for 300 ms makes `status` name that
process from its own timing report (base/canopen/peer_timing.py), not the drives; the other
one reports itself on time."""
from __future__ import annotations

import os
import signal
import time

import pytest

from spacearm.base.transport.hub import HubProcess
from spacearm.console.status_view import render_status
from hil_tests.faults import start_stack, wait_for

pytestmark = [pytest.mark.hil, pytest.mark.multiprocess]

FREEZE = 0.3     # s


@pytest.fixture
def stack(tmp_path):
    hub = HubProcess(rt_priority=50)    # `spacearm hub` as the README runs it; publishes its timing
    s = start_stack(hub, tmp_path, rig=False)
    yield hub, s
    s.close()
    hub.stop()


def freeze(pid: int, seconds: float) -> None:
    os.kill(pid, signal.SIGSTOP)
    try:
        time.sleep(seconds)
    finally:
        os.kill(pid, signal.SIGCONT)


def peers(s) -> dict:
    return s.status()["nodes"].get("peers", {})


@pytest.mark.parametrize("frozen", ["simulator", "hub"])
def test_status_names_the_frozen_process_from_its_own_report(stack, frozen):
    hub, s = stack
    # both report within their event timer (1 s) once the daemon listens
    wait_for(lambda: {"simulator", "hub"} <= set(peers(s)), 10.0, lambda: f"both reports in status: {peers(s)}")
    pid = s.sim.pid if frozen == "simulator" else hub.proc.pid
    freeze(pid, FREEZE)
    wait_for(lambda: peers(s)[frozen]["max_lateness"] >= 0.8 * FREEZE, 5.0,
             lambda: f"the {frozen}'s own report of a {FREEZE} s freeze: {peers(s)}")
    status = s.status()
    nodes = status["nodes"]
    assert nodes["peers"][frozen]["level"] == "late" and nodes["peers"][frozen]["late_cycles"] >= 1
    # its own measurement says what the late wake waited for: nothing of it ran (SIGSTOP), and
    # the advice does not tell a process at SCHED_FIFO 50 to ask for real-time priority
    assert nodes["peers"][frozen]["cause"] == "stopped", nodes["peers"][frozen]
    assert "stopped (none of its threads ran)" in nodes["message"] and "--rt-priority" not in nodes["message"]
    other = "hub" if frozen == "simulator" else "simulator"
    assert nodes["peers"][other]["max_lateness"] < 0.8 * FREEZE, nodes["peers"]
    # the warning names the frozen process first, with its own numbers; the drives are not blamed
    assert nodes["message"].startswith(f"{frozen} late: "), nodes["message"]
    assert "joint_" not in nodes["message"].split(" (the daemon sees")[0]
    text = render_status(status)
    assert f"{frozen} late: " in text and "their own timing:" in text
    if (status["stop"] or {}).get("code") in ("pdo_missing", "heartbeat_lost"):   # the daemon stopped the arm
        assert f"likely cause: the {frozen} reported itself late" in text, text
