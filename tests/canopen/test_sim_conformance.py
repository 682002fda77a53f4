"""CiA 301 behaviour of the simulated firmware that canopen's LocalNode lacks (each of these
failed before firmware_sim/sdo_session.py and the event-timer TPDOs)."""
from __future__ import annotations

import struct
import time

import can
import pytest

NODE = 1
RX, TX = 0x600 + NODE, 0x580 + NODE


@pytest.fixture
def raw(vbus, sim):
    bus = can.Bus(interface="virtual", channel=vbus.split(":", 1)[1], receive_own_messages=False)
    yield bus
    bus.shutdown()


def request(bus: can.BusABC, data: bytes, timeout: float = 0.5) -> bytes | None:
    bus.send(can.Message(arbitration_id=RX, data=data.ljust(8, b"\0"), is_extended_id=False))
    return response(bus, timeout)


def response(bus: can.BusABC, timeout: float) -> bytes | None:
    deadline = time.monotonic() + timeout
    while (left := deadline - time.monotonic()) > 0:
        msg = bus.recv(left)
        if msg is not None and msg.arbitration_id == TX:
            return bytes(msg.data)
    return None


def abort_code(frame: bytes | None) -> int | None:
    return struct.unpack_from("<L", frame, 4)[0] if frame and frame[0] == 0x80 else None


def write(bus, index: int, sub: int, value: int, size: int) -> bytes | None:
    command = 0x23 | ((4 - size) << 2)
    return request(bus, struct.pack("<BHB", command, index, sub) + value.to_bytes(size, "little"))


def test_event_driven_tpdo_is_sent_at_its_event_timer(raw):
    assert write(raw, 0x1803, 1, 0x80000480 + NODE, 4)[0] == 0x60       # TPDO4 off to map it
    assert write(raw, 0x1A03, 0, 0, 1)[0] == 0x60
    assert write(raw, 0x1A03, 1, 0x60410010, 4)[0] == 0x60
    assert write(raw, 0x1A03, 0, 1, 1)[0] == 0x60
    assert write(raw, 0x1803, 2, 255, 1)[0] == 0x60                     # event-driven
    assert write(raw, 0x1803, 5, 20, 2)[0] == 0x60                      # event timer 20 ms
    assert write(raw, 0x1803, 1, 0x480 + NODE, 4)[0] == 0x60
    raw.send(can.Message(arbitration_id=0, data=bytes([1, NODE]), is_extended_id=False))
    seen, deadline = 0, time.monotonic() + 0.5                          # no SYNC is ever sent
    while time.monotonic() < deadline:
        msg = raw.recv(0.05)
        if msg is not None and msg.arbitration_id == 0x480 + NODE:
            seen += 1
    assert seen >= 5


def test_client_abort_ends_the_transfer_and_stray_segments_get_no_data(raw):
    first = request(raw, struct.pack("<BHB", 0x40, 0x1008, 0))           # segmented upload
    assert first[0] & 0xE3 == 0x41
    raw.send(can.Message(arbitration_id=RX, data=struct.pack("<BHBL", 0x80, 0x1008, 0, 0x05040000),
                         is_extended_id=False))
    assert abort_code(request(raw, bytes([0x60]))) == 0x05040001
    assert abort_code(request(raw, bytes([0x00]))) == 0x05040001       # no download running either


def test_block_upload_that_forbids_a_protocol_switch_is_refused(raw):
    refused = request(raw, struct.pack("<BHBBB", 0xA4, 0x1008, 0, 16, 0))   # pst = 0
    assert abort_code(refused) == 0x05040001 and refused[1:4] == struct.pack("<HB", 0x1008, 0)
    switched = request(raw, struct.pack("<BHBBB", 0xA4, 0x1008, 0, 16, 200))  # small enough to switch
    assert switched[0] & 0xE0 == 0x40, hex(abort_code(switched) or 0)


def test_writing_a_nonzero_error_count_is_an_invalid_value(raw):
    assert abort_code(write(raw, 0x1003, 0, 1, 1)) == 0x06090030
    assert write(raw, 0x1003, 0, 0, 1)[0] == 0x60


def test_server_aborts_a_transfer_the_client_abandons(raw):
    assert request(raw, struct.pack("<BHB", 0x40, 0x1008, 0))[0] & 0xE3 == 0x41
    late = response(raw, 3.0)                                           # the client says nothing more
    assert abort_code(late) == 0x05040000 and late[1:4] == struct.pack("<HB", 0x1008, 0)


def test_an_expedited_upload_after_a_segmented_download_leaves_no_transfer_open(raw, sim):
    assert request(raw, struct.pack("<BHBL", 0x21, 0x6065, 0, 4))[0] == 0x60             # segmented download
    assert request(raw, bytes([0x07]) + (5000).to_bytes(4, "little"))[0] & 0xE0 == 0x20   # last segment, 4 B
    assert request(raw, struct.pack("<BHB", 0x40, 0x6065, 0))[0] & 0xE3 == 0x43          # expedited upload
    assert sim.node(NODE).sdo_session.active is None
    assert response(raw, 1.5) is None                                                    # no late abort
