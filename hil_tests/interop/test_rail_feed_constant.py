"""The `canopen` library's own master against our simulated rail drive (node 1 of
configs/bus/oru_testbed_on_rail.toml on a prismatic plant joint): it reads the factor group
608Fh/6091h/6092h over SDO, configures it as a third-party master would, and the drive's
position actual value (6064h) follows in the increments that scaling gives for the carriage's
0.3 m, as CiA 402 describes: increments = m / (feed / shaft revolutions) * gear * encoder."""
from __future__ import annotations

import time
import uuid

import canopen
import pytest

from spacearm.base.config.bus import load_bus_config
from spacearm.firmware_sim.runner import Simulator
from tests.canopen.test_linear_axis import BUS, PLANT

RAIL = 1


@pytest.fixture
def rail():
    channel = f"extrail-{uuid.uuid4().hex[:8]}"
    config = load_bus_config(BUS)
    sim = Simulator(f"virtual:{channel}", config, PLANT).start()
    network = canopen.Network()
    network.connect(interface="virtual", channel=channel, receive_own_messages=False)
    drive = network.add_node(RAIL, str(config.node(RAIL).eds_path))
    drive.nmt.state = "RESET COMMUNICATION"
    drive.nmt.wait_for_bootup(2.0)
    yield network, drive
    network.disconnect()
    sim.stop()


def _position_after_sync(network, drive) -> int:
    network.sync.transmit()          # the drive samples its actual values at SYNC
    time.sleep(0.05)
    return drive.sdo[0x6064].raw


def test_an_independent_master_reads_and_sets_the_rail_drives_feed_constant(rail):
    network, drive = rail
    # as the drive comes up: its EDS defaults (a 5 mm lead, 2^20 increments, 100:1)
    assert (drive.sdo[0x6092][1].raw, drive.sdo[0x6092][2].raw) == (5000, 1)
    assert (drive.sdo[0x608F][1].raw, drive.sdo[0x6091][1].raw) == (1 << 20, 100)
    # the rail's real factor group: 10 000 increments per motor revolution, 1:1, 10 mm lead
    drive.sdo[0x608F][1].raw = 10_000
    drive.sdo[0x6091][1].raw = 1
    drive.sdo[0x6092][1].raw = 10_000
    assert [drive.sdo[i][s].raw for i, s in ((0x608F, 1), (0x608F, 2), (0x6091, 1), (0x6091, 2),
                                             (0x6092, 1), (0x6092, 2))] == [10_000, 1, 1, 1, 10_000, 1]
    assert _position_after_sync(network, drive) == 300_000          # 0.3 m in um
    drive.sdo[0x6092][2].raw = 2                                     # 10 mm per 2 revolutions: 5 mm lead
    assert _position_after_sync(network, drive) == 600_000
