"""A burst of TPDOs decoded node by node (drivers/tpdo_burst.py) against the per-frame path:
the same values in the same dicts, the same health, arrived set and counters, on random
payloads and orders; and every burst a plan does not cover (a short, long or unknown frame, a
COB-ID twice) left to the per-frame path, which counts a bad frame and decodes the rest."""
from __future__ import annotations

import random
import struct

from spacearm.base.config.bus import load_bus_config
from spacearm.drivers.network import ArmNetwork
from spacearm.drivers.tpdo_burst import build_plan


def _nets():
    nets = [ArmNetwork("virtual:unused", load_bus_config()) for _ in range(2)]    # not connected
    for net in nets:
        net._sync = 7
    return nets


def _observed(net):
    return ({name: dict(d.values) for name, d in net.drivers.items()},
            {name: h.life_sync for name, h in net.health.items()},
            set(net._received), (net.stats.rx_frames, net.stats.tpdos, net.stats.malformed, net.stats.unknown))


def _per_frame(net, frames):
    on_frame = net.network.listeners[0].on_frame
    for can_id, data in frames:
        on_frame(can_id, data, 0.0)


def _tpdo_frames(net, rng):
    return [(spec.cob_id, bytes(rng.randrange(256) for _ in range(spec.length)))
            for d in net.drivers.values() for spec in d.tpdos]


def test_a_burst_decodes_what_its_frames_decode_one_by_one():
    rng = random.Random(35)
    burst_net, frame_net = _nets()
    for round_ in range(40):
        frames = _tpdo_frames(burst_net, rng)
        if round_ % 2:
            rng.shuffle(frames)      # another order: another plan, the same values
        if round_ % 5 == 4:
            frames = frames[: rng.randrange(2, len(frames))]    # a loopback read cut short
        burst_net.network.listeners[0].on_frames(frames, 0.0)
        _per_frame(frame_net, frames)
        assert _observed(burst_net) == _observed(frame_net)
    assert any(plan is not None for plan in burst_net._burst_plans.values())


def test_frames_a_plan_does_not_cover_go_the_per_frame_way():
    rng = random.Random(36)
    for change in ("short", "long", "unknown", "twice", "bytearray"):
        burst_net, frame_net = _nets()
        frames = _tpdo_frames(burst_net, rng)
        burst_net.network.listeners[0].on_frames(frames, 0.0)     # the plan for this order exists
        _per_frame(frame_net, frames)
        frames = _tpdo_frames(burst_net, rng)
        i = rng.randrange(len(frames))
        cob, data = frames[i]
        if change == "short":
            frames[i] = (cob, data[:-1])
        elif change == "long":
            frames[i] = (cob, (data + b"\xAA" * 8)[:8]) if len(data) < 8 else (cob, data[:-1])
        elif change == "unknown":
            frames.insert(i, (0x7E, b"\x01\x02"))
        elif change == "twice":
            frames.insert(i, (cob, bytes(len(data))))
        else:
            frames = [(c, bytearray(d)) for c, d in frames]
        burst_net.network.listeners[0].on_frames(frames, 0.0)
        _per_frame(frame_net, frames)
        assert _observed(burst_net) == _observed(frame_net), change
    assert burst_net.stats.malformed == 0


def test_a_short_frame_in_a_burst_is_counted_and_the_others_decoded():
    burst_net, _ = _nets()
    frames = _tpdo_frames(burst_net, random.Random(37))
    frames[3] = (frames[3][0], frames[3][1][:1])
    burst_net.network.listeners[0].on_frames(frames, 0.0)
    assert burst_net.stats.malformed == 1 and burst_net.stats.tpdos == len(frames) - 1
    assert frames[3][0] not in burst_net._received


class _Codec:
    def __init__(self, fmt: str, length: int):
        self.struct = struct.Struct(fmt)
        self.length = length


class _Route:
    """A compiled TPDO route as cyclic_io.TpdoRoute has it, for odd mappings."""

    def __init__(self, driver, health, fmt, keys, length):
        self.driver, self.health, self.codec = driver, health, _Codec(fmt, length)
        self.keys, self.length = keys, length
        self.unpack = self.codec.struct.unpack_from


def test_odd_mappings_interleaved_nodes_padding_and_the_same_object_twice():
    """Two nodes' frames interleaved, a PDO longer than its mapped entries, one object mapped
    twice (the later frame wins, as frame by frame), a frame without a struct: no plan."""
    a, b = type("D", (), {})(), type("D", (), {})()
    ha, hb = object(), object()
    routes = {
        0x181: _Route(a, ha, "<hB", ((1, 0), (2, 0)), 3),
        0x182: _Route(b, hb, "<i", ((3, 0),), 4),
        0x281: _Route(a, ha, "<H", ((1, 0),), 5),           # 3 bytes beyond the entries
        0x282: _Route(b, hb, "<bbbbbbbb", tuple((4, i) for i in range(8)), 8),
    }
    ids = (0x181, 0x182, 0x281, 0x282)
    plan = build_plan(ids, routes)
    rng = random.Random(38)
    for _ in range(50):
        payloads = [bytes(rng.randrange(256) for _ in range(routes[c].length)) for c in ids]
        joined = b"".join(payloads)
        expected = {id(a): {}, id(b): {}}
        for cob, data in zip(ids, payloads):
            r = routes[cob]
            expected[id(r.driver)].update(zip(r.keys, r.unpack(data)))
        got = {id(a): {}, id(b): {}}
        for node in plan.nodes:
            got[id(node.driver)].update(zip(node.keys, node.unpack(joined, node.offset)))
        assert got == expected
    assert plan.lengths == (3, 4, 5, 8) and plan.cobs == frozenset(ids)
    routes[0x281].unpack = None                   # coded entry by entry (24-bit, strings)
    assert build_plan(ids, routes) is None
    assert build_plan((0x181, 0x181), routes) is None
    assert build_plan((0x181, 0x7E), routes) is None


def test_a_plan_that_cannot_be_built_is_said_once_and_the_frames_still_decoded(monkeypatch, caplog):
    import spacearm.drivers.cyclic_io as cyclic_io

    def broken(ids, routes):
        raise RuntimeError("broken plan")
    monkeypatch.setattr(cyclic_io, "build_plan", broken)
    burst_net, frame_net = _nets()
    rng = random.Random(39)
    for _ in range(3):
        frames = _tpdo_frames(burst_net, rng)
        burst_net.network.listeners[0].on_frames(frames, 0.0)
        _per_frame(frame_net, frames)
        assert _observed(burst_net) == _observed(frame_net)
    lines = [r for r in caplog.records if "no TPDO burst plan" in r.getMessage()]
    assert len(lines) == 1 and "0x18" in lines[0].getMessage()
