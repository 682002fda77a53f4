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
