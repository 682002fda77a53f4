"""Every transport passes the same tests (bus_spec: virtual, loopback, socketcan when vcan0 exists)."""
from __future__ import annotations

import os
import threading
import time

import can
import pytest

pytestmark = [pytest.mark.vcan_vm]


def _frame(i: int, arb: int = 0x123) -> can.Message:
    return can.Message(arbitration_id=arb, data=i.to_bytes(4, "big") + b"\xA5\x5A", is_extended_id=False)


def _collect(bus: can.BusABC, n: int, timeout: float, arb: int | None = None, idle: float | None = None
             ) -> list[can.Message]:
    """Receive up to n frames (of id arb); give up after `timeout`, or after `idle` seconds
    without any frame once the first one arrived (so a lossy transport fails fast)."""
    got: list[can.Message] = []
    now = time.monotonic()
    deadline = now + timeout
    last = None
    while len(got) < n and now < deadline:
        if idle is not None and last is not None and now - last > idle:
            break
        msg = bus.recv(min(0.2, max(0.0, deadline - now)))
        now = time.monotonic()
        if msg is not None:
            last = now
            if arb is None or msg.arbitration_id == arb:
                got.append(msg)
    return got


def _drain(bus: can.BusABC, quiet: float = 0.1) -> None:
    while bus.recv(quiet) is not None:
        pass


def test_send_receive_between_two_buses(bus_spec, open_test_bus, time_scale):
    a, b = open_test_bus(bus_spec), open_test_bus(bus_spec)
    _drain(b)
    sent = [
        can.Message(arbitration_id=0x080, data=b"", is_extended_id=False),  # SYNC: no data
        can.Message(arbitration_id=0x181, data=bytes(range(8)), is_extended_id=False),
        can.Message(arbitration_id=0x1ABCDEF0, data=b"\x01\x02", is_extended_id=True),
        can.Message(arbitration_id=0x601, is_remote_frame=True, dlc=8, is_extended_id=False),
    ]
    for m in sent:
        a.send(m)
    got = _collect(b, len(sent), 5 * time_scale)
    assert [(m.arbitration_id, m.is_extended_id, m.is_remote_frame, bytes(m.data), m.dlc) for m in got] == \
           [(m.arbitration_id, m.is_extended_id, m.is_remote_frame, bytes(m.data), m.dlc) for m in sent]
    assert all(m.timestamp > 0 for m in got)


def test_order_preserved_and_no_self_reception(bus_spec, open_test_bus, time_scale):
    a, b = open_test_bus(bus_spec), open_test_bus(bus_spec)
    _drain(a)
    _drain(b)
    for i in range(200):
        a.send(_frame(i))
    got = _collect(b, 200, 10 * time_scale, arb=0x123, idle=2 * time_scale)
    assert [int.from_bytes(m.data[:4], "big") for m in got] == list(range(200))
    # the sender never sees its own frames
    assert a.recv(0.3) is None
    # and the bus works the other way round too
    b.send(_frame(7, 0x124))
    back = _collect(a, 1, 5 * time_scale)
    assert back and back[0].arbitration_id == 0x124


def test_three_nodes_all_receive_every_other_nodes_frames(bus_spec, open_test_bus, time_scale):
    a, b, c = (open_test_bus(bus_spec) for _ in range(3))
    for bus in (a, b, c):
        _drain(bus, 0.05)
    a.send(_frame(1, 0x101))
    b.send(_frame(2, 0x102))
    got_c = {m.arbitration_id for m in _collect(c, 2, 5 * time_scale)}
    got_a = {m.arbitration_id for m in _collect(a, 1, 5 * time_scale)}
    got_b = {m.arbitration_id for m in _collect(b, 1, 5 * time_scale)}
    assert got_c == {0x101, 0x102}
    assert got_a == {0x102} and got_b == {0x101}


def test_notifier_delivers_frames(bus_spec, open_test_bus, time_scale):
    a, b = open_test_bus(bus_spec), open_test_bus(bus_spec)
    _drain(b)
    reader = can.BufferedReader()
    seen: list[int] = []
    done = threading.Event()

    def on_msg(msg):
        seen.append(int.from_bytes(msg.data[:4], "big"))
        if len(seen) >= 50:
            done.set()

    notifier = can.Notifier(b, [reader, on_msg], timeout=0.05)
    try:
        for i in range(50):
            a.send(_frame(i))
        assert done.wait(10 * time_scale), f"notifier saw only {len(seen)} of 50 frames"
    finally:
        notifier.stop(2)
    assert seen == list(range(50))
    assert reader.get_message(0.1) is not None


def test_burst_of_1000_frames_without_loss(bus_spec, open_test_bus, time_scale):
    """The receiver reads in its own thread while the burst goes out (as a Notifier does)."""
    a, b = open_test_bus(bus_spec), open_test_bus(bus_spec)
    _drain(b)
    got: list[can.Message] = []
    reader = threading.Thread(target=lambda: got.extend(_collect(b, 1000, 20 * time_scale, arb=0x123,
                                                                   idle=2 * time_scale)), daemon=True)
    reader.start()
    for i in range(1000):
        a.send(_frame(i))
    reader.join(25 * time_scale)
    seqs = [int.from_bytes(m.data[:4], "big") for m in got]
    assert len(seqs) == 1000, f"lost {1000 - len(seqs)} of 1000 frames"
    assert seqs == list(range(1000))


def test_burst_of_1000_frames_read_after_the_burst(bus_spec, open_test_bus, time_scale):
    """Nobody reads during the burst: the receive queue must hold 1000 frames (SocketCAN:
    the factory enlarges SO_RCVBUF, which needs root/CAP_NET_ADMIN past net.core.rmem_max)."""
    if bus_spec.startswith("socketcan:") and os.geteuid() != 0:
        try:
            rmem_max = int(open("/proc/sys/net/core/rmem_max").read())
        except (OSError, ValueError):
            rmem_max = 0
        if rmem_max < 2 * 1024 * 1024:
            pytest.skip(f"not root and net.core.rmem_max={rmem_max}: a socket queues only ~{rmem_max // 384} "
                        "frames (sysctl -w net.core.rmem_max=8388608 to run this)")
    a, b = open_test_bus(bus_spec), open_test_bus(bus_spec)
    _drain(b)
    for i in range(1000):
        a.send(_frame(i))
    got = _collect(b, 1000, 20 * time_scale, arb=0x123, idle=2 * time_scale)
    seqs = [int.from_bytes(m.data[:4], "big") for m in got]
    assert len(seqs) == 1000, f"lost {1000 - len(seqs)} of 1000 frames"
    assert seqs == list(range(1000))


def test_error_frame_does_not_break_the_bus(bus_spec, open_test_bus, time_scale):
    a, b = open_test_bus(bus_spec), open_test_bus(bus_spec)
    _drain(b)
    try:
        a.send(can.Message(arbitration_id=0x004, is_error_frame=True, dlc=8, data=bytes(8), is_extended_id=False))
    except can.CanError:
        pass  # a transport may refuse to inject error frames; it must say so with a CanError
    a.send(_frame(42, 0x222))
    got = _collect(b, 1, 5 * time_scale, arb=0x222)
    assert got and int.from_bytes(got[0].data[:4], "big") == 42


def test_oversized_frame_is_refused(bus_spec, open_test_bus):
    a = open_test_bus(bus_spec)
    bad = can.Message(arbitration_id=0x123, data=bytes(8), is_extended_id=False, check=False)
    bad.data = bytearray(12)  # a classic CAN frame with 12 data bytes
    bad.dlc = 12
    with pytest.raises((can.CanError, ValueError)):
        a.send(bad)


# ----------------------------------------------------------------- across processes
@pytest.mark.multiprocess
def test_round_trip_with_another_process(bus_spec, open_test_bus, peer, time_scale):
    echo = peer(bus_spec, "echo")
    bus = open_test_bus(bus_spec)
    for i in range(20):
        bus.send(_frame(i, 0x300))
    got = _collect(bus, 20, 10 * time_scale, arb=0x301)
    assert [int.from_bytes(m.data[:4], "big") for m in got] == list(range(20))
    bus.send(can.Message(arbitration_id=0x7FF, is_extended_id=False))
    assert echo.result(20 * time_scale)["echoed"] >= 20


@pytest.mark.multiprocess
def test_burst_of_1000_frames_from_another_process(bus_spec, open_test_bus, peer, time_scale):
    sender = peer(bus_spec, "burst", "--count", "1000", "--base-id", "0x321", "--start-id", "0x0AA")
    bus = open_test_bus(bus_spec)
    _drain(bus, 0.05)
    bus.send(can.Message(arbitration_id=0x0AA, is_extended_id=False))
    got = _collect(bus, 1000, 30 * time_scale, arb=0x321, idle=3 * time_scale)
    seqs = [int.from_bytes(m.data[:4], "big") for m in got]
    assert sender.result(30 * time_scale)["sent"] == 1000
    assert len(seqs) == 1000, f"lost {1000 - len(seqs)} of 1000 frames"
    assert seqs == list(range(1000))
