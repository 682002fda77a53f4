"""The cheap cycle's fast paths against their reference: frames as plain values on the
in-process bus vs python-can Messages, PDO codecs compiled once per mapping vs the canopen
library's per-entry coding, and the simulated node's compiled RPDO decoder vs LocalNode.set_data."""
from __future__ import annotations

import random
import struct
import uuid

import can
import pytest

from spacearm.base.canopen import od
from spacearm.base.config.bus import load_bus_config
from spacearm.base.transport import frame_sender, open_bus
from spacearm.drivers.network import ArmNetwork
from spacearm.firmware_sim.runner import Simulator


class _Raw(can.Listener):
    def __init__(self):
        self.frames = []

    def on_frame(self, can_id, data, timestamp):
        self.frames.append((can_id, bytes(data)))

    def on_message_received(self, msg):
        self.frames.append((msg.arbitration_id, bytes(msg.data)))


class _MessagesOnly(can.Listener):
    def __init__(self):
        self.frames = []

    def on_message_received(self, msg):
        assert not msg.is_extended_id and not msg.is_remote_frame and msg.is_rx
        self.frames.append((msg.arbitration_id, bytes(msg.data)))


def test_send_frame_delivers_what_send_does_to_every_kind_of_receiver():
    name = f"virtual:fast-{uuid.uuid4().hex[:8]}"
    sender, inline_raw, inline_msg, queued = (open_bus(name) for _ in range(4))
    try:
        raw, msgs = _Raw(), _MessagesOnly()
        inline_raw.add_inline_listener(raw)
        inline_msg.add_inline_listener(msgs)
        frames = [(0x80, b""), (0x201, bytes(range(8))), (0x7FF, b"\x01")]
        fast = frame_sender(sender)
        for can_id, data in frames:
            fast(can_id, data)
        for can_id, data in frames:
            sender.send(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
        assert raw.frames == frames * 2 and msgs.frames == frames * 2
        got = [queued.recv(1.0) for _ in range(6)]
        assert [(m.arbitration_id, bytes(m.data)) for m in got] == frames * 2
        assert all(m.is_rx and not m.is_extended_id and m.dlc == len(m.data) for m in got)
        with pytest.raises(can.CanOperationError):
            fast(0x800, b"")            # not a standard identifier
        with pytest.raises(can.CanOperationError):
            fast(0x100, bytes(9))       # more than 8 bytes
    finally:
        for bus in (sender, inline_raw, inline_msg, queued):
            bus.shutdown()


def test_compiled_pdo_codecs_match_the_library_coding():
    net = ArmNetwork("virtual:unused", load_bus_config())     # not connected: drivers and layouts only
    rng = random.Random(3)
    checked = 0
    for driver in net.drivers.values():
        for spec in driver.tpdos:
            data = bytes(rng.randrange(256) for _ in range(spec.length))
            driver.decode(spec, data)
            fast = dict(driver.values)
            offset, reference = 0, {}
            for e in spec.entries:
                reference[(e.index, e.sub)] = e.var.decode_raw(data[offset:offset + e.size])
                offset += e.size
            assert {k: fast[k] for k in reference} == reference
            checked += 1
        for spec in driver.rpdos:
            for e in spec.entries:
                size = e.size * 8
                value = rng.randrange(2 ** (size - 1)) if e.var.data_type in (2, 3, 4) else rng.randrange(2 ** size)
                driver.rpdo_values[(e.index, e.sub)] = value
        for (cob, data), spec in zip(driver.rpdo_frames(), driver.rpdos):
            reference = b"".join(e.var.encode_raw(driver.rpdo_values.get((e.index, e.sub), 0)) for e in spec.entries)
            assert data == reference, spec
            checked += 1
    assert checked >= 20


def test_compiled_rpdo_decoder_stores_what_set_data_stores():
    bus = f"virtual:fast-{uuid.uuid4().hex[:8]}"
    sim = Simulator(bus, load_bus_config()).start()
    try:
        node = sim.node("joint_1")
        node.nmt_state = od.NMT_STATE_OPERATIONAL
        node.rpdo_cob_ids()
        rng = random.Random(5)
        for cob, pdo in node._rpdos.items():
            data = bytes(rng.randrange(256) for _ in range(pdo.length))
            if any(index == od.MODES_OF_OPERATION for index, _, _ in pdo.entries):
                continue    # value range checked by the device (tested in test_sim_conformance)
            node.on_rpdo(cob, data)
            fast = {(i, s): node.raw(i, s) for i, s, _ in pdo.entries}
            offset = 0
            for index, sub, size in pdo.entries:      # the reference: the library's set_data
                node.local.set_data(index, sub, data[offset:offset + size])
                offset += size
            assert fast == {(i, s): node.raw(i, s) for i, s, _ in pdo.entries}
            assert fast[pdo.entries[0][:2]] == data[:pdo.entries[0][2]]
    finally:
        sim.stop()


def test_settings_cache_follows_every_write():
    bus = f"virtual:fast-{uuid.uuid4().hex[:8]}"
    sim = Simulator(bus, load_bus_config()).start()
    try:
        node = sim.node("joint_1")
        before = node.param(od.MAX_TORQUE)
        node.put(od.MAX_TORQUE, 0, before + 1)                       # firmware write
        assert node.param(od.MAX_TORQUE) == before + 1
        node.local.set_data(od.MAX_TORQUE, 0, struct.pack("<H", before + 2))   # SDO download
        assert node.param(od.MAX_TORQUE) == before + 2
        node.reset(application=True)                                 # power-on values again
        assert node.param(od.MAX_TORQUE) == before
    finally:
        sim.stop()
