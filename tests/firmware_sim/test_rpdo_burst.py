"""The simulator routes a burst of frames with the compiled core (_simcore.c rpdo_burst: the
RPDOs that take its direct path stored in one call) as the pure-Python path does, frame by
frame: the same stored bytes, param() caches, statistics, EMCYs and answers, whatever the
frames (RPDOs of any length, NMT commands between them, unknown COB-IDs), the nodes' states
(stopped, silent, behind a line gate) and a device reaction that raises."""
from __future__ import annotations

from hypothesis import given, settings, strategies as st

from spacearm.base.canopen import od
from spacearm.firmware_sim import simcore
from spacearm.firmware_sim.runner import Simulator
from tests.firmware_sim.core_switch import core_switched, needs_core

_SIMS: list[Simulator] = []


def _simulator(sent: list) -> Simulator:
    """The default bus config's nodes powered on and OPERATIONAL, not on a bus: what they send
    goes to `sent`. Built once (loading the EDS files is slow) and reset for each example."""
    if not _SIMS:
        _SIMS.append(Simulator("virtual:rpdo-burst-test"))
    sim = _SIMS[0]
    sim.bus = object()        # not None: the simulator sends, into _send_frame below
    sim._send_frame = lambda cob, data: sent.append((cob, bytes(data)))
    sim.stats = type(sim.stats)()
    for node in sim.nodes.values():
        node.faults = type(node.faults)()
        node.__dict__.pop("on_rpdo", None)
        node.power_on()
        node.stats = type(node.stats)()
        node.on_nmt(od.NMT_START)
    sim._dirty = True
    return sim


def _state(sim: Simulator) -> str:
    nodes = [(node.node_id, node.nmt_state, sorted((i, sorted(v.items())) for i, v in node.local.data_store.items()),
              sorted(node._params.items()), node.stats) for node in sim.nodes.values()]
    return repr((nodes, sim.stats))


class _Refusing(Exception):
    """A device reaction's bug (not an SDO abort): the frame is an internal error, the rest goes on."""


@needs_core
@settings(max_examples=200, deadline=None)
@given(frames=st.lists(st.tuples(st.integers(0, 19), st.one_of(st.binary(min_size=8, max_size=8),
                                                               st.binary(max_size=8))), max_size=24),
       stopped=st.sets(st.integers(0, 7), max_size=2), silent=st.sets(st.integers(0, 7), max_size=2),
       gated=st.sets(st.integers(0, 7), max_size=2), raising=st.sets(st.integers(0, 7), max_size=2))
def test_a_burst_routed_in_the_core_is_routed_as_python_routes_it(frames, stopped, silent, gated, raising):
    traces = []
    for use_core in (True, False):
        sent: list = []
        sim = _simulator(sent)
        nodes = list(sim.nodes.values())
        cobs = sorted(cob for node in nodes for cob in node.rpdo_cob_ids())
        extra = [od.NMT_COB_ID, 0x7FF, od.SDO_RX_BASE + 0x7E, od.HEARTBEAT_BASE + 0x7F]
        burst = [(cob, bytes(8)) for cob in cobs]     # each RPDO's decoder compiled (by Python) first
        for which, data in frames:
            if which < len(cobs):
                burst.append((cobs[which], data))
            elif which - len(cobs) < len(extra):
                cob = extra[which - len(cobs)]
                if cob == od.NMT_COB_ID:        # stop or start one node in the middle of the burst
                    command = od.NMT_STOP if data[:1] < b"\x80" else od.NMT_START
                    data = bytes([command, nodes[which % len(nodes)].node_id])
                elif cob == od.HEARTBEAT_BASE + 0x7F:
                    data = data[:1]
                burst.append((cob, data))
        for i, node in enumerate(nodes):
            if i in stopped:
                node.on_nmt(od.NMT_STOP)
            node.faults.silent = i in silent
            if i in gated:          # a line gate (firmware_sim/line_selection.py) that lets every frame through
                node.on_rpdo = lambda cob, data, original=node.on_rpdo: original(cob, data)
            if i in raising:
                def refuse(index, sub, data):
                    raise _Refusing(f"0x{index:04X}")
                node.on_write = refuse
        with core_switched(use_core):
            sim._route_frames(burst)
        for node in nodes:
            node.__dict__.pop("on_write", None)
            node.__dict__.pop("on_rpdo", None)
        traces.append((_state(sim), sent))
    assert traces[0] == traces[1]


@needs_core
def test_the_direct_path_takes_the_cycle_rpdos_and_leaves_the_rest():
    """The core stops at a frame that is not an RPDO of its routes and hands it to Python, then
    goes on; a frame of a node behind a line gate is Python's: the gate sees it; so is the first
    frame of an RPDO, whose decoder Python compiles."""
    sent: list = []
    sim = _simulator(sent)
    sim._rebuild_routes()
    first = [(cob, b"\0" * 8) for cob in sorted(sim._rpdo_direct)]
    assert simcore.core.rpdo_burst(first, 0, sim._rpdo_direct, sim.stats, Exception, od.NMT_STATE_OPERATIONAL) == 0
    sim._route_frames(first)
    cobs = sorted(sim._rpdo_direct)
    assert cobs and set(cobs) == set(sim._rpdo_routes)
    seen = []
    node = sim._rpdo_routes[cobs[0]]
    node.on_rpdo = lambda cob, data, original=node.on_rpdo: (seen.append(cob), original(cob, data))
    try:
        assert simcore.core.rpdo_burst([(cobs[1], b"\0" * 8), (0x7FF, b""), (cobs[1], b"\0" * 8)], 0, sim._rpdo_direct,
                                       sim.stats, Exception, od.NMT_STATE_OPERATIONAL) == 1
        assert simcore.core.rpdo_burst([(cobs[0], b"\0" * 8)], 0, sim._rpdo_direct, sim.stats, Exception,
                                       od.NMT_STATE_OPERATIONAL) == 0
        sim._route_frames([(cobs[0], b"\0" * 8), (cobs[1], b"\0" * 8)])
        assert seen == [cobs[0]]
    finally:
        node.__dict__.pop("on_rpdo", None)


def _mode_offsets(sim: Simulator) -> dict:
    """{cob: byte offset of the mode of operation} of the RPDOs that map it."""
    out = {}
    for node in sim.nodes.values():
        for cob, pdo in (node.pdo_engine.rpdos or {}).items():
            offset = 0
            for index, _, size in pdo.entries:
                if index == od.MODES_OF_OPERATION:
                    out[cob] = offset
                offset += size
    return out


@needs_core
@settings(max_examples=100, deadline=None)
@given(bursts=st.lists(st.lists(st.sampled_from([8, 1, 3, 0, -1]), min_size=1, max_size=6), min_size=1, max_size=5))
def test_modes_of_operation_routed_in_the_core_are_stored_as_python_stores_them(bursts):
    """Bursts carrying modes of operation the drives take or refuse, again and again: the core
    skips the drive's check for a chunk it passed before (SimNode.pure_write_check), and stores,
    refuses and counts as the pure-Python path does."""
    traces = []
    for use_core in (True, False):
        sent: list = []
        sim = _simulator(sent)
        cobs = sorted(cob for node in sim.nodes.values() for cob in node.rpdo_cob_ids())
        with core_switched(use_core):
            sim._route_frames([(cob, bytes(8)) for cob in cobs])
            offsets = _mode_offsets(sim)
            assert offsets
            trace = []
            for modes in bursts:
                burst = []
                for n, (cob, at) in enumerate(sorted(offsets.items())):
                    data = bytearray(8)
                    data[at] = modes[n % len(modes)] & 0xFF
                    burst.append((cob, bytes(data)))
                sim._route_frames(burst)
                trace.append(_state(sim))
        traces.append((trace, sent))
    assert traces[0] == traces[1]


@needs_core
def test_an_unchanged_mode_of_operation_is_checked_once():
    """The drive's on_write runs for a mode of operation it has not let pass yet, not again for
    the same bytes; a refused mode is checked every time; a patched on_write is always called."""
    import sys
    from spacearm.firmware_sim.joint_drive import JointDriveNode
    sent: list = []
    sim = _simulator(sent)
    cobs = sorted(cob for node in sim.nodes.values() for cob in node.rpdo_cob_ids())
    sim._route_frames([(cob, bytes(8)) for cob in cobs])
    offsets = _mode_offsets(sim)
    for node in sim.nodes.values():
        node.__dict__.get("_accepted_writes", {}).clear()
    calls = []
    code = JointDriveNode.on_write.__code__

    def profile(frame, event, arg):
        if event == "call" and frame.f_code is code:
            calls.append(frame.f_locals["data"])

    def burst(mode):
        frames = []
        for cob, at in sorted(offsets.items()):
            data = bytearray(8)
            data[at] = mode & 0xFF
            frames.append((cob, bytes(data)))
        return frames

    sys.setprofile(profile)
    try:
        sim._route_frames(burst(8))
        first = len(calls)
        sim._route_frames(burst(8))
        second = len(calls) - first
        sim._route_frames(burst(3))
        sim._route_frames(burst(3))
        refused = len(calls) - first - second
    finally:
        sys.setprofile(None)
    assert first == len(offsets) and second == 0 and refused == 2 * len(offsets)
    assert sim.stats.internal_errors == 0
