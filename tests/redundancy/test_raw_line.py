"""While every simulated node listens on one line, the simulator takes that line's frames
without tagging them and its nodes' line gates are off (base/transport/rx_gating.py); what a
node hears must be what it heard with the gates always on: its own line's frames only, whether
a frame comes inline from an in-process sender or through the pair's queue, and once one node
has toggled away, each node its own line's."""
from __future__ import annotations

import time
import uuid

import can
import pytest

from spacearm.base.canopen import od
from spacearm.base.canopen import redundancy_object as rdn
from spacearm.base.config.bus import load_bus_config
from spacearm.base.transport import open_bus
from spacearm.base.transport.line_faults import clear_all, line_fault
from spacearm.firmware_sim.runner import Simulator

MASTER = 127


def _nmt(bus: can.BusABC, command: int, node_id: int, message: bool = False) -> None:
    """As plain values where the bus takes them (the in-process bus's hot path), else as a Message."""
    if hasattr(bus, "send_frame") and not message:
        bus.send_frame(od.NMT_COB_ID, bytes([command, node_id]))
    else:
        bus.send(can.Message(arbitration_id=od.NMT_COB_ID, data=[command, node_id], is_extended_id=False))


def _states(sim: Simulator) -> set[int]:
    return {node.nmt_state for node in sim.nodes.values()}


def _until(condition, seconds: float = 2.0) -> bool:
    end = time.monotonic() + seconds
    while not condition() and time.monotonic() < end:
        time.sleep(0.005)
    return condition()


@pytest.fixture
def sim_on_pair():
    tag = uuid.uuid4().hex[:8]
    lines = (f"virtual:raw-a-{tag}", f"virtual:raw-b-{tag}")
    sim = Simulator("+".join(lines), load_bus_config()).start()
    # in-process senders (inline delivery) and python-can's own bus (through the pair's queue)
    inline = tuple(open_bus(spec) for spec in lines)
    queued = tuple(can.Bus(interface="virtual", channel=spec.partition(":")[2]) for spec in lines)
    try:
        yield sim, inline, queued, lines
    finally:
        for bus in inline + queued:
            bus.shutdown()
        sim.stop()
        clear_all()


def test_the_other_lines_frames_stay_off_the_nodes_while_their_line_goes_untagged(sim_on_pair):
    sim, inline, queued, lines = sim_on_pair
    gating = sim.bus.rx_gating
    assert gating.raw_line == 0
    for sender, message in ((inline[1], False), (inline[1], True), (queued[1], True)):   # line B: no node there
        _nmt(sender, od.NMT_START, 0, message)
        time.sleep(0.1)
        assert _states(sim) == {od.NMT_STATE_PRE_OPERATIONAL}
    assert _until(lambda: gating.raw_line == 0), "the hold of the queued frame was not given back"
    _nmt(inline[0], od.NMT_START, 0)               # line A: every node
    assert _states(sim) == {od.NMT_STATE_OPERATIONAL}
    _nmt(queued[0], od.NMT_STOP, 0)
    assert _until(lambda: _states(sim) == {od.NMT_STATE_STOPPED})
    # a fault on the line ends untagged delivery at once, and its mending brings it back
    line_fault(lines[0]).set("intermittent", loss=0.0)
    assert gating.raw_line is None
    line_fault(lines[0]).clear()
    assert gating.raw_line == 0


def test_once_a_node_has_toggled_each_node_hears_its_own_line(sim_on_pair):
    sim, inline, _, _ = sim_on_pair
    node, rule = sim.nodes[1], sim.line_selection.rules[1]
    node.put(od.CONSUMER_HEARTBEAT, rdn.MASTER_CONSUMER_SUB, (MASTER << 16) | 60)
    _nmt(inline[0], od.NMT_START, 0)
    inline[0].send_frame(od.HEARTBEAT_BASE + MASTER, bytes([od.NMT_STATE_OPERATIONAL]))
    assert _until(lambda: rule.line == 1), "node 1 did not toggle when the master fell silent"
    assert sim.bus.rx_gating.raw_line is None
    _nmt(inline[0], od.NMT_STOP, 0)                # line A: every node but node 1
    assert node.nmt_state == od.NMT_STATE_OPERATIONAL
    assert {n.nmt_state for i, n in sim.nodes.items() if i != 1} == {od.NMT_STATE_STOPPED}
    _nmt(inline[1], od.NMT_STOP, 0)                # line B: node 1 alone
    assert _states(sim) == {od.NMT_STATE_STOPPED}
