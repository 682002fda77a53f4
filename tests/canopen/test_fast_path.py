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


class _Bursts(_Raw):
    def __init__(self):
        super().__init__()
        self.calls = 0

    def on_frames(self, frames, timestamp):
        self.calls += 1
        self.frames += [(can_id, bytes(data)) for can_id, data in frames]


def test_a_burst_reaches_every_kind_of_receiver_whole_and_in_order():
    """send_frames: a receiver that takes bursts gets one call, the others every frame in
    order (inline or queued), and a tap sees the burst before any receiver."""
    name = f"virtual:burst-{uuid.uuid4().hex[:8]}"
    sender, bursts_bus, raw_bus, queued, tap_bus = (open_bus(name) for _ in range(5))
    try:
        seen = []

        class Tap(_Raw):
            def on_frame(self, can_id, data, timestamp):
                seen.append(("tap", can_id, len(bursts.frames)))

        bursts, raw = _Bursts(), _Raw()
        bursts_bus.add_inline_listener(bursts)
        raw_bus.add_inline_listener(raw)
        tap_bus.add_tap(Tap())
        frames = [(0x80, b""), (0x201, bytes(range(8))), (0x7FF, b"\x01")]
        sender.send_frames(frames)
        assert bursts.calls == 1 and bursts.frames == frames and raw.frames == frames
        assert seen == [("tap", can_id, 0) for can_id, _ in frames]    # every frame before the receivers
        got = [queued.recv(1.0) for _ in range(3)]
        assert [(m.arbitration_id, bytes(m.data)) for m in got] == frames
        with pytest.raises(can.CanOperationError):
            sender.send_frames([(0x100, b""), (0x800, b"")])     # checked whole before any frame goes out
        assert bursts.frames == frames
    finally:
        for bus in (sender, bursts_bus, raw_bus, queued, tap_bus):
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


def test_queued_and_inline_frames_decode_a_tpdo_alike_and_bad_frames_only_count():
    """The network's listener takes frames as python-can Messages (loopback, SocketCAN, the
    in-process bus's queued fallback) and as plain values (inline): one receive path decodes
    both, and a short, remote or extended frame is counted, never raised."""
    nets = [ArmNetwork("virtual:unused", load_bus_config()) for _ in range(2)]   # not connected
    spec = nets[0].drivers["joint_1"].tpdos[0]
    data = bytes(range(1, spec.length + 1))
    queued, inline = (net.network.listeners[0] for net in nets)
    queued.on_message_received(can.Message(arbitration_id=spec.cob_id, data=data, is_extended_id=False))
    inline.on_frame(spec.cob_id, data, 0.0)
    assert nets[0].drivers["joint_1"].values == nets[1].drivers["joint_1"].values != {}
    queued.on_message_received(can.Message(arbitration_id=spec.cob_id, data=data[:-1], is_extended_id=False))
    queued.on_message_received(can.Message(arbitration_id=spec.cob_id, is_remote_frame=True, is_extended_id=False))
    queued.on_message_received(can.Message(arbitration_id=0x1ABCDE, data=data, is_extended_id=True))
    inline.on_frame(spec.cob_id, b"", 0.0)
    stats = [vars(net.stats) for net in nets]
    assert [(s["rx_frames"], s["tpdos"], s["malformed"], s["ignored"]) for s in stats] == [(4, 1, 1, 2), (2, 1, 1, 0)]


def test_a_new_layout_is_compiled_for_the_frames_that_follow():
    """Codecs are built with the layout, not per frame: a driver given another mapping decodes
    and encodes by that one from the next frame on."""
    net = ArmNetwork("virtual:unused", load_bus_config())
    driver = net.drivers["joint_1"]
    rpdos, tpdos = driver.rpdos, driver.tpdos
    swapped = [type(tpdos[0])(s.kind, s.number, s.cob_id, list(reversed(s.entries))) for s in tpdos]
    driver.set_layout(rpdos, swapped)
    spec = swapped[0]
    data = bytes(range(1, spec.length + 1))
    driver.decode(spec, data)
    offset, expected = 0, {}
    for e in spec.entries:
        expected[(e.index, e.sub)] = e.var.decode_raw(data[offset:offset + e.size])
        offset += e.size
    assert {k: driver.values[k] for k in expected} == expected
    assert driver.tpdo_codecs[spec.cob_id].spec is spec and driver.tpdos == tuple(swapped)


def test_a_joint_state_built_without_init_is_the_dataclass_built_one():
    """JointDriver.state() fills JointState's fields directly: every field, in order, the same
    values as JointState(...) with them (a field added to the dataclass must be added there)."""
    import dataclasses
    from spacearm.drivers.devices import JointState
    net = ArmNetwork("virtual:unused", load_bus_config())
    driver = net.drivers["joint_1"]
    rng = random.Random(5)
    for spec in driver.tpdos:
        driver.decode(spec, bytes(rng.randrange(256) for _ in range(spec.length)))
    state = driver.state()
    names = [f.name for f in dataclasses.fields(JointState)]
    assert list(vars(state)) == names
    assert repr(state) == repr(JointState(**{name: getattr(state, name) for name in names}))
