"""The redundant-pair bus (base/transport/redundant.py) and its line faults, on in-process
buses: what a plain bus attached to each line (a third party's view of the wire) receives."""
from __future__ import annotations

import time
import uuid

import can
import pytest

from spacearm.base.transport import BusSpecError, open_bus
from spacearm.base.transport.line_faults import BABBLE_BURST, BABBLE_ID, LineFaultError, clear_all, line_fault
from spacearm.base.transport.redundant import rx_line


@pytest.fixture
def lines():
    tag = uuid.uuid4().hex[:8]
    a, b = f"virtual:red-a-{tag}", f"virtual:red-b-{tag}"
    yield a, b
    clear_all()


def drain(bus: can.BusABC, wait: float = 0.05) -> list[can.Message]:
    out, deadline = [], time.monotonic() + wait
    while time.monotonic() < deadline:
        msg = bus.recv(0.01)
        if msg is not None:
            out.append(msg)
    return out


def test_sends_on_the_active_line_only(lines):
    a, b = lines
    pair, tap_a, tap_b = open_bus(f"{a}+{b}"), open_bus(a), open_bus(b)
    try:
        pair.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
        pair.active = 1
        pair.send(can.Message(arbitration_id=0x701, data=b"\x05", is_extended_id=False))
        assert [m.arbitration_id for m in drain(tap_a)] == [0x080]
        assert [m.arbitration_id for m in drain(tap_b)] == [0x701]
    finally:
        for bus in (pair, tap_a, tap_b):
            bus.shutdown()


def test_receives_both_lines_tagged(lines):
    a, b = lines
    pair, tap_a, tap_b = open_bus(f"{a}+{b}"), open_bus(a), open_bus(b)
    seen = []
    pair.rx_observers.append(lambda line, can_id, data, t: seen.append((line, can_id)))
    try:
        tap_a.send(can.Message(arbitration_id=0x181, data=b"\x01", is_extended_id=False))
        tap_b.send(can.Message(arbitration_id=0x182, data=b"\x02", is_extended_id=False))
        got = []
        for _ in range(2):
            msg = pair.recv(1.0)
            got.append((rx_line(), msg.arbitration_id))
        assert sorted(got) == [(0, 0x181), (1, 0x182)]
        assert sorted(seen) == [(0, 0x181), (1, 0x182)]
    finally:
        for bus in (pair, tap_a, tap_b):
            bus.shutdown()


def test_a_read_frames_line_ends_with_its_pair(lines):
    """rx_line() names the line of the frame recv() handed out until the pair shuts down, then
    None: a lockstep stack run later in this thread took its own frames for line B's and
    lost both lines (test_lockstep_determinism's line-cut run after this file)."""
    a, b = lines
    pair, tap_b = open_bus(f"{a}+{b}"), open_bus(b)
    try:
        tap_b.send(can.Message(arbitration_id=0x182, data=b"\x02", is_extended_id=False))
        assert pair.recv(1.0) is not None
        assert rx_line() == 1
    finally:
        pair.shutdown()
        tap_b.shutdown()
    assert rx_line() is None


def test_inline_listeners_see_the_line(lines):
    a, b = lines
    pair, tap_b = open_bus(f"{a}+{b}"), open_bus(b)

    class Recorder(can.Listener):
        def __init__(self):
            self.frames = []

        def on_frame(self, can_id, data, timestamp):
            self.frames.append((rx_line(), can_id, data))

        def on_message_received(self, msg):
            self.frames.append((rx_line(), msg.arbitration_id, bytes(msg.data)))

    rec = Recorder()
    pair.add_inline_listener(rec)
    try:
        tap_b.send_frame(0x283, b"\x07")
        assert rec.frames == [(1, 0x283, b"\x07")]
    finally:
        pair.shutdown()
        tap_b.shutdown()


def test_tx_router_sends_each_frame_on_its_senders_line(lines):
    a, b = lines
    pair, tap_a, tap_b = open_bus(f"{a}+{b}"), open_bus(a), open_bus(b)
    pair.tx_router = lambda can_id: {0x701: 0, 0x702: 1}.get(can_id)
    try:
        pair.send_frames([(0x701, b"\x05"), (0x702, b"\x05"), (0x7FD, b"\x00")])
        assert sorted(m.arbitration_id for m in drain(tap_a)) == [0x701, 0x7FD]
        assert sorted(m.arbitration_id for m in drain(tap_b)) == [0x702, 0x7FD]
    finally:
        for bus in (pair, tap_a, tap_b):
            bus.shutdown()


def test_cut_line_passes_nothing_either_way(lines):
    a, b = lines
    pair, tap_a = open_bus(f"{a}+{b}"), open_bus(a)
    line_fault(a).set("cut")
    try:
        pair.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
        tap_a.send(can.Message(arbitration_id=0x181, data=b"\x01", is_extended_id=False))
        assert drain(tap_a) == []
        assert pair.recv(0.1) is None
        line_fault(a).clear()
        pair.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
        assert [m.arbitration_id for m in drain(tap_a)] == [0x080]
    finally:
        pair.shutdown()
        tap_a.shutdown()


def test_babbling_node_floods_the_line_with_high_priority_frames(lines):
    a, b = lines
    pair, tap_a = open_bus(f"{a}+{b}"), open_bus(a)
    line_fault(a).set("babble")
    try:
        for _ in range(3):
            pair.send(can.Message(arbitration_id=0x201, data=b"\x00" * 8, is_extended_id=False))
        got = drain(tap_a)
        assert [m.arbitration_id for m in got] == [BABBLE_ID] * (3 * BABBLE_BURST)
        assert line_fault(a).frames_lost == 3
    finally:
        pair.shutdown()
        tap_a.shutdown()


def test_stuck_dominant_line_shows_error_frames(lines):
    a, b = lines
    pair, tap_a = open_bus(f"{a}+{b}"), open_bus(a)
    line_fault(a).set("stuck_dominant")
    try:
        pair.send(can.Message(arbitration_id=0x201, data=b"\x01", is_extended_id=False))
        got = drain(tap_a)
        assert got and all(m.is_error_frame for m in got)
    finally:
        pair.shutdown()
        tap_a.shutdown()


@pytest.mark.parametrize("mode,loss", [("intermittent", 0.5), ("error_passive", 0.2)])
def test_random_loss_close_to_its_probability_and_repeatable(lines, mode, loss):
    a, b = lines
    pair, tap_a = open_bus(f"{a}+{b}"), open_bus(a)
    runs = []
    try:
        for _ in range(2):
            line_fault(a).set(mode, loss=loss, seed=7)
            for i in range(400):
                pair.send_frame(0x181, bytes([i & 0xFF]))
            runs.append([m.data[0] for m in drain(tap_a, 0.2)])
        assert runs[0] == runs[1]                       # seeded: the same frames lost
        assert abs(len(runs[0]) / 400 - (1 - loss)) < 0.08
    finally:
        pair.shutdown()
        tap_a.shutdown()


def test_bad_pairs_and_modes_are_one_clear_error(lines):
    a, b = lines
    with pytest.raises(BusSpecError, match="one transport"):
        open_bus(f"{a}+loopback:x")
    with pytest.raises(BusSpecError, match="must differ"):
        open_bus(f"{a}+{a}")
    with pytest.raises(BusSpecError, match="two lines"):
        open_bus(f"{a}+{b}+virtual:c")
    with pytest.raises(LineFaultError, match="unknown line fault"):
        line_fault(a).set("melted")
    with pytest.raises(LineFaultError, match="within 0..1"):
        line_fault(a).set("intermittent", loss=1.5)
