"""The API's status waits for the real-time cycle's idle time (controller/daemon/idle_gate.py)."""
from __future__ import annotations

import threading
import time

from spacearm.controller.daemon.clock import RealTimeClock
from spacearm.controller.daemon.idle_gate import IdleGate


def _read_in_thread(gate: IdleGate, log: list[str]) -> threading.Thread:
    def read():
        gate.wait_for_idle()
        log.append("read")
    thread = threading.Thread(target=read)
    thread.start()
    return thread


def test_without_deadlines_the_gate_is_open():
    gate = IdleGate()
    gate.cycle_started()              # a lockstep cycle: no deadline is ever handed over
    gate.wait_for_idle()
    gate.cycle_ended(None)
    gate.wait_for_idle()
    assert gate.waits == 0


def test_a_read_during_a_cycle_runs_after_the_cycle_ended():
    gate, log = IdleGate(max_wait=30.0), []
    gate.cycle_ended(time.monotonic() + 10.0)    # an earlier cycle: the next deadline far ahead
    gate.cycle_started()
    reader = _read_in_thread(gate, log)
    reader.join(0.2)
    assert log == [] and reader.is_alive()
    log.append("cycle ended")
    gate.cycle_ended(time.monotonic() + 10.0)
    reader.join(30.0)
    assert log == ["cycle ended", "read"] and gate.waits == 1


def test_a_read_just_before_a_deadline_waits_for_that_cycle_to_end():
    gate, log = IdleGate(guard=5.0, max_wait=30.0), []
    gate.cycle_ended(time.monotonic() + 1.0)     # the next wake is inside the guard
    reader = _read_in_thread(gate, log)
    reader.join(0.2)
    assert log == []
    gate.cycle_started()
    log.append("cycle ended")
    gate.cycle_ended(time.monotonic() + 60.0)
    reader.join(30.0)
    assert log == ["cycle ended", "read"]


def test_a_stalled_cycle_does_not_stall_the_read():
    gate, log = IdleGate(max_wait=0.05), []
    gate.cycle_ended(time.monotonic() + 10.0)
    gate.cycle_started()                          # ... and never ends
    reader = _read_in_thread(gate, log)
    reader.join(30.0)
    assert log == ["read"]


def test_the_real_time_clock_names_its_next_deadline():
    now = [100.0]
    clock = RealTimeClock(0.02, now=lambda: now[0], sleep=lambda s: now.__setitem__(0, now[0] + s))
    assert clock.next_deadline is None
    clock.next_tick()
    assert clock.next_deadline == 100.02
    clock.next_tick()
    assert abs(clock.next_deadline - 100.04) < 1e-12
