"""The simulator sends a SYNC's TPDOs with the compiled core (_simcore.c tpdo_burst: the nodes on
its direct path sampled and batched in one call) as the pure-Python path sends them, node by
node: the same frames in the same order, SYNC counters and statistics, whatever the nodes'
states (stopped, silent, ignoring SYNC, dropping or shortening frames, behind a line gate, a
mapped object missing from the store) over several SYNCs."""
from __future__ import annotations

from hypothesis import given, settings, strategies as st

from spacearm.base.canopen import od
from spacearm.firmware_sim import simcore
from spacearm.firmware_sim.runner import Simulator
from tests.firmware_sim.core_switch import core_switched, needs_core

_SIMS: list[Simulator] = []


def _simulator(sent: list) -> Simulator:
    """The default bus config's nodes powered on and OPERATIONAL, not on a bus: the bursts they
    send go to `sent`. Built once (loading the EDS files is slow) and reset for each example."""
    if not _SIMS:
        _SIMS.append(Simulator("virtual:tpdo-burst-test"))
    sim = _SIMS[0]
    sim.bus = object()        # not None: the simulator sends, into the senders below
    sim._send_frame = lambda cob, data: sent.append((cob, bytes(data)))
    sim._send_frames = lambda frames: sent.append(("burst", [(cob, bytes(data)) for cob, data in frames]))
    for node in sim.nodes.values():
        faults = node.faults
        faults.silent = faults.ignore_sync = False
        faults.drop_tx = faults.corrupt_tx = 0
        node.__dict__.pop("send_tpdos", None)
        node.power_on()
        node.on_nmt(od.NMT_START)
        node.stats = type(node.stats)()
    return sim


def _state(sim: Simulator) -> str:
    return repr([(node.node_id, node.stats, node.pdo_engine.sync_counter, node.faults) for node in sim.nodes.values()])


@needs_core
@settings(max_examples=150, deadline=None)
@given(syncs=st.integers(1, 4), stopped=st.sets(st.integers(0, 7), max_size=2),
       silent=st.sets(st.integers(0, 7), max_size=2), ignoring=st.sets(st.integers(0, 7), max_size=2),
       dropping=st.sets(st.integers(0, 7), max_size=2), shortening=st.sets(st.integers(0, 7), max_size=2),
       gated=st.sets(st.integers(0, 7), max_size=2), forgetting=st.sets(st.integers(0, 7), max_size=2))
def test_a_syncs_tpdos_from_the_core_are_the_python_tpdos(syncs, stopped, silent, ignoring, dropping, shortening,
                                                          gated, forgetting):
    traces = []
    for use_core in (True, False):
        sent: list = []
        sim = _simulator(sent)
        with core_switched(use_core):
            sim._on_sync()             # every node's tables and compiled rows made
            for i, node in enumerate(sim.nodes.values()):
                if i in stopped:
                    node.on_nmt(od.NMT_STOP)
                node.faults.silent = i in silent
                node.faults.ignore_sync = i in ignoring
                node.faults.drop_tx = 1 if i in dropping else 0
                node.faults.corrupt_tx = 2 if i in shortening else 0
                if i in gated:      # a line gate (firmware_sim/line_selection.py) that lets the node send
                    node.send_tpdos = lambda original=node.send_tpdos: original()
                if i in forgetting:     # a mapped object not stored (yet): Python samples through raw()
                    pdo = node.pdo_engine.tpdos[0]
                    index, sub, _ = pdo.entries[0]
                    node.local.data_store[index].pop(sub, None)
            for _ in range(syncs):
                sim._on_sync()
        for node in sim.nodes.values():
            node.__dict__.pop("send_tpdos", None)
        traces.append((sent, _state(sim)))
    assert traces[0] == traces[1]


@needs_core
def test_the_core_leaves_a_gated_node_to_its_gate_and_goes_on():
    sent: list = []
    sim = _simulator(sent)
    sim._on_sync()
    nodes = list(sim.nodes.values())
    seen = []
    nodes[2].send_tpdos = lambda original=nodes[2].send_tpdos: (seen.append(2), original())
    try:
        sim._batch, sim._batch_thread = [], None
        assert simcore.core.tpdo_burst(nodes, 0, sim._tpdo_direct, sim._batch, od.NMT_STATE_OPERATIONAL) == 2
        assert simcore.core.tpdo_burst(nodes, 3, sim._tpdo_direct, sim._batch, od.NMT_STATE_OPERATIONAL) == len(nodes)
        sim._batch = None
        sim._on_sync()
        assert seen == [2]
    finally:
        nodes[2].__dict__.pop("send_tpdos", None)
