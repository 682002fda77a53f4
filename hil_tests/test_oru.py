"""The ORU changeout over the CAN bus (virtual bus, lockstep): the full task flow, and a
failure injected in the subtasks that react differently, each ending in a protective stop
with the reason kept and the ORU never dropped."""
from __future__ import annotations

import numpy as np
import pytest

from spacearm.base.canopen import od
from hil_tests.oru_stack import OruStack

pytestmark = pytest.mark.hil


@pytest.fixture
def stack(tmp_path):
    s = OruStack(record_dir=tmp_path / "runs")
    s.ready()
    yield s
    s.close()


def test_full_changeout_completes(stack):
    world = stack.world
    assert world.orus["old_oru"].store == "exposed" and world.orus["new_oru"].store == "airlock_new"
    stack.call("oru.run")
    status = stack.run_to_end()
    assert status["state"] == "done", status["failure"]
    assert stack.daemon.core.state == "enabled"
    assert [(r["stage"] + 1, r["number"]) for r in status["records"]] == \
        [(1, n) for n in range(1, 7)] + [(2, n) for n in range(7, 14)] + \
        [(3, n) for n in range(1, 7)] + [(4, n) for n in range(7, 14)]
    # Plant truth: the old ORU is latched in the airlock slot, the new one in the exposed store.
    assert world.orus["old_oru"].where == "store" and world.orus["old_oru"].store == "airlock_empty"
    assert world.orus["new_oru"].where == "store" and world.orus["new_oru"].store == "exposed"
    assert world.latched == {"exposed": True, "airlock_empty": True, "airlock_new": False}
    for name, store in (("old_oru", "airlock_empty"), ("new_oru", "exposed")):
        rel = np.linalg.inv(world.slots[store] @ world.slot_T_oru) @ world.orus[name].pose
        assert np.hypot(rel[0, 3], rel[1, 3]) < 1.0e-3 and abs(rel[2, 3]) < 1.0e-3
    inserts = [r for r in status["records"] if r["number"] == 9]
    assert all(2.5 < r["peak_insert_force"] < 20.0 for r in inserts)
    # Back at the initial pose.
    q = stack.daemon.snapshot.measurement.q
    assert np.max(np.abs(q - np.array(stack.daemon.arm.postures["ready"]))) < 2e-3


def _assert_safe_stop(stack, status, words):
    assert status["state"] in ("failed", "interrupted")
    assert any(w in (status["failure"] or "") for w in words), status["failure"]
    stack.wait(lambda: not np.any(stack.daemon.snapshot.measurement.joints_enabled), 10)
    assert stack.daemon.core.state == "stopped"
    assert stack.world.orus["old_oru"].where != "loose"        # never dropped


def test_end_effector_jam_while_clamping_stops_safely(stack):
    stack.call("oru.run", stages=[1, 2])
    stack.run_until(1, 4)
    stack.sim.node("end_effector").inject_fault(od.EMCY_EE_JAM)
    _assert_safe_stop(stack, stack.run_to_end(), ("end effector", "emcy", "EMCY", "fault"))


def test_latch_that_does_not_release_stops_the_extraction(stack):
    stack.world.latch_jammed = True
    stack.call("oru.run", stages=[1, 2])
    status = stack.run_to_end()
    _assert_safe_stop(stack, status, ("contact wrench", "force/torque"))
    assert status["subtask"] == 6


def test_blocked_slot_stops_the_insertion(stack):
    # Another ORU already sits in the destination slot (plant truth only).
    stack.world.orus["new_oru"].store = "airlock_empty"
    stack.world.orus["new_oru"].pose = stack.world.slots["airlock_empty"] @ stack.world.slot_T_oru
    stack.call("oru.run", stages=[1, 2])
    status = stack.run_to_end()
    _assert_safe_stop(stack, status, ("jammed or blocked", "contact wrench"))
    assert status["subtask"] == 9


def test_pause_resume_and_abort(stack):
    stack.call("oru.run", stages=[1])
    stack.run_until(1, 2)
    # pause slows the flow to rest along its path (controller/oru/runner.py PauseRamp), then holds
    assert stack.call("oru.pause") in ("pausing", "paused")
    stack.wait(lambda: stack.oru_status()["state"] == "paused", 30)
    held = stack.daemon.snapshot.command.q.copy()
    cycle = stack.daemon.snapshot.tick.cycle
    stack.wait(lambda: stack.daemon.snapshot.tick.cycle > cycle + 25, 30)
    np.testing.assert_allclose(stack.daemon.snapshot.command.q, held, atol=1e-12)
    assert stack.call("oru.resume") in ("resuming", "running")
    stack.wait(lambda: stack.oru_status()["state"] == "running", 30)
    stack.run_until(1, 3)
    assert stack.call("oru.abort") == "aborted"
    stack.wait(lambda: stack.daemon.snapshot.mode == "hold", 10)
    assert stack.daemon.core.state == "enabled"
    assert stack.oru_status()["state"] == "aborted"
