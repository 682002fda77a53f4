"""What the master takes from the line it does not drive (drivers/line_redundancy.py): the
nodes' heartbeats and EMCYs, never process data. Frames are put on the standby line by a
plain bus attached to it, as another device on that wire would."""
from __future__ import annotations

from spacearm.base.canopen import od
from spacearm.base.transport import open_bus


def test_standby_line_pdos_are_not_decoded_but_its_heartbeats_are_watched(pair):
    pair.run(0.2)
    standby = pair.master.active ^ 1
    joint = pair.net.joints[0]
    cob = next(c for c, (driver, _) in pair.net._tpdo_routes.items() if driver is joint)
    before = pair.net.read().joints[0]
    other_device = open_bus(pair.lines[standby])
    try:
        # a TPDO of the first joint on the standby line, with values nobody sent: the master
        # does not run process data off a line it does not drive
        other_device.send_frame(cob, bytes([0x5A] * 8))
        after = pair.net.read().joints[0]
        assert after == before
        # ... yet its rule saw the frame: a node heard there counts for choosing the line
        assert joint.node_id in pair.master.heard[standby]
        # the same node's heartbeat on the standby line reaches the health monitor
        other_device.send_frame(od.HEARTBEAT_BASE + joint.node_id, bytes([od.NMT_STATE_PRE_OPERATIONAL]))
        assert pair.net.read().nodes[joint.name].nmt_state == od.NMT_STATE_PRE_OPERATIONAL
    finally:
        other_device.shutdown()
    assert pair.master.active == standby ^ 1       # two stray frames move no network
