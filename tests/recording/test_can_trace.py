"""The raw CAN trace sees every frame on the bus, in-process (virtual) or as a child process."""
from __future__ import annotations

import time

import can
import pytest

from spacearm.controller.recording.can_trace import CanTrace
from spacearm.base.transport import BusSpecError, open_bus
from spacearm.base.transport.hub import LoopbackHub


def _frames(n: int) -> list[can.Message]:
    return [can.Message(arbitration_id=0x180 + i % 8, data=bytes([i % 256, 1, 2]), is_extended_id=False)
            for i in range(n)]


def _send_and_trace(spec: str, path, n: int = 200) -> list[can.Message]:
    trace = CanTrace(spec, path)
    sender = open_bus(spec)
    try:
        for msg in _frames(n):
            sender.send(msg)
        time.sleep(0.5)      # frames reach the tap before it is told to stop
    finally:
        sender.shutdown()
        trace.stop()
    return list(can.CanutilsLogReader(str(path)))


@pytest.mark.parametrize("kind", ["virtual", "loopback"])
def test_trace_has_every_frame_in_order(kind, tmp_path):
    hub = LoopbackHub("127.0.0.1", 0).start() if kind == "loopback" else None
    try:
        spec = f"loopback:trace@127.0.0.1:{hub.port}" if hub else f"virtual:trace-{time.monotonic_ns()}"
        logged = _send_and_trace(spec, tmp_path / "run.can.log")
    finally:
        if hub:
            hub.stop()
    sent = _frames(200)
    assert [(m.arbitration_id, bytes(m.data)) for m in logged] == [(m.arbitration_id, bytes(m.data)) for m in sent]


def test_in_process_trace_is_in_wire_order_when_a_receiver_answers_inline(tmp_path):
    """A simulated node answers a SYNC inside the sender's call (lockstep): the trace still has
    the SYNC first and its answers after it, with times that never go back, as candump on a
    real bus would (a tap that was one more receiver logged the answers first)."""
    spec = f"virtual:order-{time.monotonic_ns()}"
    node, master = open_bus(spec), open_bus(spec)

    class Answers(can.Listener):
        def on_frame(self, can_id, data, timestamp):
            if can_id == 0x080:
                for k in range(3):
                    node.send_frame(0x181 + k, data)

        def on_message_received(self, msg):
            pass
    node.add_inline_listener(Answers())
    trace = CanTrace(spec, tmp_path / "order.can.log")
    try:
        for i in range(5):
            master.send_frame(0x080, bytes([i]))
        time.sleep(0.5)
    finally:
        trace.stop()
        node.shutdown()
        master.shutdown()
    logged = list(can.CanutilsLogReader(str(tmp_path / "order.can.log")))
    assert [(m.arbitration_id, m.data[0]) for m in logged] == \
        [(can_id, i) for i in range(5) for can_id in (0x080, 0x181, 0x182, 0x183)]
    assert [m.timestamp for m in logged] == sorted(m.timestamp for m in logged)


def test_bus_the_child_cannot_open_is_a_clear_error(tmp_path):
    # no such SocketCAN interface (or no SocketCAN at all): the child says why and exits
    with pytest.raises(RuntimeError, match="CAN trace did not start: can_trace: cannot open socketcan:nosuchcan7"):
        CanTrace("socketcan:nosuchcan7", tmp_path / "x.can.log")


def test_bad_bus_spec_is_refused_before_starting(tmp_path):
    with pytest.raises(BusSpecError):
        CanTrace("carrier-pigeon:1", tmp_path / "x.can.log")


@pytest.mark.parametrize("kind", ["virtual", "loopback"])
def test_trace_of_a_redundant_pair_names_each_frames_line(kind, tmp_path):
    """Frames put on each line by plain buses (a third party on the wire): the trace's channel
    column is the line each came on, as `candump -l any` names the interface."""
    hub = LoopbackHub("127.0.0.1", 0).start() if kind == "loopback" else None
    tag = time.monotonic_ns()
    lines = [f"loopback:tr-{x}-{tag}@127.0.0.1:{hub.port}" if hub else f"virtual:tr-{x}-{tag}" for x in "ab"]
    path = tmp_path / "pair.can.log"
    trace = CanTrace("+".join(lines), path)
    senders = [open_bus(spec) for spec in lines]
    try:
        for i in range(40):     # both ways a sender puts a frame on a line (the stack's hot path: send_frame)
            sender, can_id = senders[i % 3 == 0], 0x181 + (i % 3 == 0)
            if i % 2 and hasattr(sender, "send_frame"):
                sender.send_frame(can_id, bytes([i]))
            else:
                sender.send(can.Message(arbitration_id=can_id, data=bytes([i]), is_extended_id=False))
        time.sleep(0.5)
    finally:
        for sender in senders:
            sender.shutdown()
        trace.stop()
        if hub:
            hub.stop()
    logged = list(can.CanutilsLogReader(str(path)))
    assert len(logged) == 40
    names = {0x181: f"tr-a-{tag}", 0x182: f"tr-b-{tag}"}
    assert [m.channel for m in logged if m.arbitration_id == 0x182] == [names[0x182]] * 14
    assert all(m.channel == names[m.arbitration_id] for m in logged)


def test_the_child_tap_runs_below_the_cycle_once_it_is_on_the_bus(tmp_path):
    """Started at the daemon's niceness (a niced start-up got the CPU last on a busy machine),
    then niceness 10, read back from the kernel, so the trace never takes CPU from the cycle."""
    import os

    from spacearm.controller.recording.can_trace import CHILD_NICENESS
    hub = LoopbackHub("127.0.0.1", 0).start()
    trace = CanTrace(f"loopback:nice@127.0.0.1:{hub.port}", tmp_path / "nice.can.log")
    try:
        deadline = time.monotonic() + 10.0
        while os.getpriority(os.PRIO_PROCESS, trace._proc.pid) != os.getpriority(os.PRIO_PROCESS, 0) + CHILD_NICENESS:
            assert time.monotonic() < deadline, os.getpriority(os.PRIO_PROCESS, trace._proc.pid)
            time.sleep(0.01)
    finally:
        trace.stop()
        hub.stop()


def test_in_process_bus_trace_is_formatted_in_another_process(tmp_path, monkeypatch):
    """The virtual bus's tap only collects frames here (issue 35): no candump line is formatted
    in this process, and the child's trace still has every frame in order."""
    from spacearm.base.transport import tap as tap_module

    def not_here(*args, **kwargs):
        raise AssertionError("CAN trace formatted in the daemon's process")
    monkeypatch.setattr(tap_module.BufferedTap, "flush", not_here)
    monkeypatch.setattr(can.CanutilsLogWriter, "on_message_received", not_here)
    logged = _send_and_trace(f"virtual:trace-{time.monotonic_ns()}", tmp_path / "run.can.log")
    assert [(m.arbitration_id, bytes(m.data)) for m in logged] == [(m.arbitration_id, bytes(m.data))
                                                                   for m in _frames(200)]
