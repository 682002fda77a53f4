"""The daemon keeps the arm moving through a bus line switch (lockstep, in one process, a
redundant pair of virtual lines): a joint move with the nominal line cut mid-motion, then
the redundant line failing later (back to nominal), and both lines lost. Judged from the
recording (positions, events) and the drives' own reports, not from the master's state."""
from __future__ import annotations

import uuid

import numpy as np
import pytest

from spacearm.base.transport.line_faults import clear_all, line_fault
from spacearm.controller.recording.mcap_reader import read_recording
from tests.daemon.lockstep_script import scripted_daemon

PLANT = "configs/plant/oru_testbed_nominal.toml"
STOP_KINDS = {"protective_stop", "stop"}


@pytest.fixture
def lines():
    tag = uuid.uuid4().hex[:8]
    yield f"virtual:dmn-a-{tag}", f"virtual:dmn-b-{tag}"
    clear_all()


def recorded(runs) -> tuple[list[dict], list[dict]]:
    [path] = runs.glob("*.mcap")
    rec = read_recording(path)
    return [m.data for m in rec.topic("/cycle")], [m.data for m in rec.topic("/events")]


def move_through(script, goal, cut_after: int, fault) -> int:
    """Start a joint move to `goal`, apply `fault()` `cut_after` cycles into it, run to its end."""
    finished = script.daemon.status()["motions_finished"]
    script.call("move_joints", q=list(goal))
    script.run(cut_after)
    fault()
    script.run_until(lambda s: s["motions_finished"] > finished or s["state"] != "enabled", 3000, "end of the move")
    script.run(10)
    return script.cycle


def test_joint_move_continues_through_a_cut_and_back(tmp_path, lines):
    with scripted_daemon(PLANT, record_dir=tmp_path, bus="+".join(lines)) as script:
        home = np.array([j["q"] for j in script.daemon.status()["joints"]])
        out = home + np.array([0.3, -0.2, 0.25, 0.0, 0.0, 0.0])
        move_through(script, out, 30, lambda: line_fault(lines[0]).set("cut"))
        mid = script.daemon.status()
        assert mid["state"] == "enabled", mid["stop_reason"]
        assert mid["network"]["bus_lines"]["active"] == "B"
        # the redundant line fails later: back to the (restored) nominal one, mid-motion again
        line_fault(lines[0]).clear()
        move_through(script, home, 30, lambda: line_fault(lines[1]).set("cut"))
        status = script.daemon.status()
        assert status["state"] == "enabled", status["stop_reason"]
        lines_status = status["network"]["bus_lines"]
        print(f"bus lines: {lines_status}; TPDO waits timed out: {status['network']['tpdo_timeouts']}")
        assert lines_status["active"] == "A" and lines_status["switches"] >= 2
    cycles, events = recorded(tmp_path)
    kinds = [e["kind"] for e in events]
    assert kinds.count("line_switch_complete") >= 2, kinds
    assert not STOP_KINDS & set(kinds), kinds
    q = np.array([c["q"] for c in cycles])
    reached_out = np.flatnonzero(np.all(np.abs(q - out) < 2e-3, axis=1))
    assert reached_out.size, "the first move never reached its goal"
    assert np.all(np.abs(q[-1] - home) < 2e-3), q[-1] - home       # and the second one its own


def test_both_lines_lost_is_a_protective_stop_with_its_own_code(tmp_path, lines):
    with scripted_daemon(PLANT, record_dir=tmp_path, bus="+".join(lines)) as script:
        home = np.array([j["q"] for j in script.daemon.status()["joints"]])

        def cut_both():
            line_fault(lines[0]).set("cut")
            line_fault(lines[1]).set("cut")
        move_through(script, home + np.array([0.3, 0.0, 0.0, 0.0, 0.0, 0.0]), 30, cut_both)
        script.run(20)
        status = script.daemon.status()
    assert status["state"] == "stopped"
    assert status["stop"]["code"] == "bus_lines_lost", status["stop_reason"]
