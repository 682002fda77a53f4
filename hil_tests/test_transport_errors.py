"""Bad specs, absent hub, malformed streams, reconnects: clear errors, never a hang."""
from __future__ import annotations

import socket
import threading
import time

import can
import pytest

from spacearm.base.transport import BusSpecError, open_bus, parse_bus_spec
from spacearm.base.transport.loopback import HubUnavailableError, LoopbackBus, parse_spec
from spacearm.base.transport.hub import HubProcess


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("spec", ["", "vcan0", "virtual:", "canbus:x", "loopback:a@nohost", "loopback:@127.0.0.1:1",
                                  "loopback:a@127.0.0.1:99999", "socketcan:../etc", "socketcan:name with space"])
def test_bad_spec_is_a_bus_spec_error(spec):
    with pytest.raises(BusSpecError) as exc:
        open_bus(spec)
    assert spec.split(":")[0] in str(exc.value) or "expected" in str(exc.value)


def test_spec_forms():
    assert parse_bus_spec("virtual:arm") == ("virtual", "arm")
    assert parse_spec("arm@127.0.0.1:4000") == ("arm", "127.0.0.1", 4000)
    assert parse_spec("127.0.0.1:4000") == ("default", "127.0.0.1", 4000)
    assert parse_spec("4000") == ("default", "127.0.0.1", 4000)
    name, host, port = parse_spec("arm")
    assert name == "arm" and host and port


def test_absent_hub_gives_a_clear_error_quickly():
    port = _free_port()
    t0 = time.monotonic()
    with pytest.raises(HubUnavailableError) as exc:
        open_bus(f"loopback:x@127.0.0.1:{port}", autostart=False)
    assert time.monotonic() - t0 < 3
    text = str(exc.value)
    assert f"127.0.0.1:{port}" in text and "spacearm hub" in text
    assert isinstance(exc.value, can.CanInitializationError)


def test_a_port_that_is_not_a_hub_is_rejected():
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    port = srv.getsockname()[1]

    def talk():
        conn, _ = srv.accept()
        conn.sendall(b"HTTP/1.0 400 Bad Request\r\n\r\n")
        time.sleep(0.5)
        conn.close()

    t = threading.Thread(target=talk, daemon=True)
    t.start()
    try:
        with pytest.raises(HubUnavailableError, match="not a spacearm loopback hub"):
            open_bus(f"loopback:x@127.0.0.1:{port}", autostart=False, connect_timeout=1.0)
    finally:
        srv.close()
        t.join(2)


def test_socketcan_without_interface_is_a_clear_error():
    with pytest.raises(can.CanInitializationError) as exc:
        open_bus("socketcan:nosuchcan7")
    assert "nosuchcan7" in str(exc.value)


def test_hub_drops_a_client_that_sends_garbage_and_keeps_serving_the_others(loopback_hub):
    spec = loopback_hub.spec()
    a, b = open_bus(spec), open_bus(spec)
    try:
        for garbage in (b"\x05\x09hello", b"\x00", b"\x07\x01\x00\x00\x00\x01\x23\x00", bytes(300)):
            raw = socket.create_connection((loopback_hub.host, loopback_hub.port), timeout=2)
            raw.sendall(garbage)
            raw.settimeout(3)
            try:
                assert raw.recv(100) == b""  # hub hangs up on it
            except ConnectionResetError:
                pass
            raw.close()
        a.send(can.Message(arbitration_id=0x55, data=b"ok", is_extended_id=False))
        msg = b.recv(3)
        assert msg is not None and bytes(msg.data) == b"ok"
    finally:
        a.shutdown()
        b.shutdown()


def test_client_reconnects_when_the_hub_restarts():
    hub = HubProcess()
    port = hub.port
    spec = f"loopback:re@127.0.0.1:{port}"
    a = open_bus(spec, autostart=False, reconnect_timeout=10)
    b = open_bus(spec, autostart=False, reconnect_timeout=10)
    try:
        a.send(can.Message(arbitration_id=0x10, is_extended_id=False))
        assert b.recv(3) is not None
        hub.stop()
        hub = HubProcess(port=port)
        # b notices on its next receive, a on its next send (first send may go to the dead socket)
        deadline = time.monotonic() + 10
        got = None
        while got is None and time.monotonic() < deadline:
            a.send(can.Message(arbitration_id=0x11, is_extended_id=False))
            got = b.recv(0.3)
        assert got is not None and got.arbitration_id == 0x11
        assert a.reconnects + b.reconnects >= 2
    finally:
        a.shutdown()
        b.shutdown()
        hub.stop()


def test_hub_gone_for_good_raises_instead_of_hanging():
    hub = HubProcess()
    bus = open_bus(f"loopback:gone@127.0.0.1:{hub.port}", autostart=False, reconnect_timeout=1)
    try:
        hub.stop()
        t0 = time.monotonic()
        with pytest.raises(can.CanOperationError, match="no loopback CAN hub"):
            for _ in range(5):
                bus.recv(1)
        assert time.monotonic() - t0 < 6
    finally:
        bus.shutdown()


def test_first_client_starts_the_hub_itself(monkeypatch):
    monkeypatch.setenv("SPACEARM_HUB_IDLE_EXIT", "2")
    port = _free_port()
    spec = f"loopback:auto@127.0.0.1:{port}"
    a = open_bus(spec)  # nothing listens: a starts a hub
    b = open_bus(spec)
    try:
        a.send(can.Message(arbitration_id=0x77, data=b"\x01", is_extended_id=False))
        msg = b.recv(3)
        assert msg is not None and msg.arbitration_id == 0x77
    finally:
        a.shutdown()
        b.shutdown()
    # the auto-started hub goes away by itself once idle
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
        except OSError:
            break
        time.sleep(0.25)
    else:
        pytest.fail("auto-started hub did not exit when idle")


def test_receive_own_messages_option(loopback_hub):
    spec = loopback_hub.spec()
    a = open_bus(spec, receive_own_messages=True)
    b = open_bus(spec)
    try:
        a.send(can.Message(arbitration_id=0x66, is_extended_id=False))
        assert a.recv(3) is not None
        assert b.recv(3) is not None
    finally:
        a.shutdown()
        b.shutdown()


def test_shutdown_unblocks_a_waiting_reader(loopback_hub):
    bus = open_bus(loopback_hub.spec())
    errors = []

    def reader():
        try:
            while True:
                bus.recv(0.2)
        except can.CanOperationError:
            errors.append("closed")

    t = threading.Thread(target=reader, daemon=True)
    t.start()
    time.sleep(0.3)
    bus.shutdown()
    t.join(3)
    assert not t.is_alive() and errors == ["closed"]


def test_loopback_bus_is_a_python_can_bus(loopback_hub):
    bus = LoopbackBus(channel="x", host=loopback_hub.host, port=loopback_hub.port)
    try:
        assert isinstance(bus, can.BusABC)
        assert "127.0.0.1" in bus.channel_info
        bus.set_filters([{"can_id": 0x100, "can_mask": 0x7FF}])
    finally:
        bus.shutdown()


def test_corrupt_stream_from_the_hub_is_detected_not_delivered():
    """A 'hub' that answers the hello correctly and then sends garbage: the client drops the
    connection, tries to reconnect, and raises a CanOperationError instead of returning junk."""
    from spacearm.base.transport import wire

    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    port = srv.getsockname()[1]

    def fake_hub():
        conn, _ = srv.accept()
        conn.recv(300)
        conn.sendall(wire.encode_welcome(1) + b"\x07\x09garbage!")
        time.sleep(2)
        conn.close()

    t = threading.Thread(target=fake_hub, daemon=True)
    t.start()
    bus = open_bus(f"loopback:x@127.0.0.1:{port}", autostart=False, reconnect_timeout=0.5)
    srv_closed = False
    try:
        srv.close()  # no second connection: the reconnect must fail
        srv_closed = True
        t0 = time.monotonic()
        with pytest.raises(can.CanOperationError):
            bus.recv(3)
        assert time.monotonic() - t0 < 3
    finally:
        if not srv_closed:
            srv.close()
        bus.shutdown()
        t.join(3)
