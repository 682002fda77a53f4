"""A simulated node on a redundant pair, as a raw master on its lines sees it: the master's
heartbeat timing out moves the node to the other line (no EMCY), any other consumed heartbeat
timing out is still the node's EMCY 8130h naming that producer (CiA 301), on the pair as on
one line. The line selection answers only the master's timeout (issue 34: it no longer wraps
the node's consumer check, which ran for every node at every timer pass)."""
from __future__ import annotations

import time
import uuid

import can

from spacearm.base.canopen import od
from spacearm.base.canopen import redundancy_object as rdn
from spacearm.base.config.bus import load_bus_config
from spacearm.firmware_sim.runner import Simulator

MASTER, OTHER = 127, 99
CONSUMER_TIME_MS = 60


def _emcys(bus: can.BusABC, node_id: int, seconds: float) -> list[bytes]:
    end, out = time.monotonic() + seconds, []
    while (left := end - time.monotonic()) > 0:
        msg = bus.recv(left)
        if msg is not None and msg.arbitration_id == od.EMCY_BASE + node_id:
            out.append(bytes(msg.data))
    return out


def test_master_timeout_toggles_and_another_producers_timeout_is_an_emcy():
    tag = uuid.uuid4().hex[:8]
    lines = (f"virtual:cons-a-{tag}", f"virtual:cons-b-{tag}")
    sim = Simulator("+".join(lines), load_bus_config()).start()
    line_a, line_b = (can.Bus(interface="virtual", channel=spec.partition(":")[2]) for spec in lines)
    try:
        node = sim.nodes[1]
        rule = sim.line_selection.rules[1]
        node.put(od.CONSUMER_HEARTBEAT, rdn.MASTER_CONSUMER_SUB, (MASTER << 16) | CONSUMER_TIME_MS)
        node.put(od.CONSUMER_HEARTBEAT, 2, (OTHER << 16) | CONSUMER_TIME_MS)
        node.put(rdn.REDUNDANCY, rdn.NTOGGLE, 8)
        line_a.send(can.Message(arbitration_id=od.NMT_COB_ID, data=[od.NMT_START, 1], is_extended_id=False))
        time.sleep(0.05)
        assert node.nmt_state == od.NMT_STATE_OPERATIONAL and rule.line == 0
        # both producers heard on line A, then only the master goes on beating
        line_a.send(can.Message(arbitration_id=od.HEARTBEAT_BASE + OTHER, data=[5], is_extended_id=False))
        end = time.monotonic() + 0.3
        emcys = []
        while time.monotonic() < end:
            line_a.send(can.Message(arbitration_id=od.HEARTBEAT_BASE + MASTER, data=[5], is_extended_id=False))
            emcys += _emcys(line_a, 1, 0.02)
        assert rule.line == 0 and node.get(rdn.REDUNDANCY, rdn.CTOGGLE) == 0    # the master kept it here
        heartbeat_errors = [e for e in emcys if int.from_bytes(e[:2], "little") == od.EMCY_HEARTBEAT_ERROR]
        assert [e[3] for e in heartbeat_errors] == [OTHER]      # the other producer's timeout, once
        # now the master falls silent: the node toggles to line B, and no EMCY names the master
        emcys = _emcys(line_a, 1, 0.3) + _emcys(line_b, 1, 0.05)    # (it searches: either line)
        assert node.get(rdn.REDUNDANCY, rdn.CTOGGLE) >= 1
        assert any(e.kind == "switch" and e.node == node.name for e in sim.line_selection.events)
        assert not [e for e in emcys if int.from_bytes(e[:2], "little") == od.EMCY_HEARTBEAT_ERROR
                    and e[3] == MASTER]
    finally:
        line_a.shutdown()
        line_b.shutdown()
        sim.stop()
