"""The `canopen` library's own master (RemoteNode, BaseNode402) against our simulated nodes:
an implementation nobody here wrote checks NMT, identity, SDO, PDOs, SYNC and CiA 402."""
from __future__ import annotations

import time
import uuid

import canopen
import pytest
from canopen.profiles.p402 import BaseNode402
from canopen.sdo import SdoAbortedError

from spacearm.base.config.bus import load_bus_config
from spacearm.firmware_sim.runner import Simulator

JOINT = 2           # node ID of the joint drive under test


@pytest.fixture
def rig():
    channel = f"extmaster-{uuid.uuid4().hex[:8]}"
    config = load_bus_config()
    sim = Simulator(f"virtual:{channel}", config).start()
    network = canopen.Network()
    network.connect(interface="virtual", channel=channel, receive_own_messages=False)
    drive = BaseNode402(JOINT, str(config.node(JOINT).eds_path))
    network.add_node(drive)
    drive.nmt.state = "RESET COMMUNICATION"
    drive.nmt.wait_for_bootup(2.0)
    yield network, sim, drive
    network.sync.stop()
    for pdo in drive.rpdo.map.values():
        pdo.stop()
    network.disconnect()
    sim.stop()


def test_nmt_heartbeat_and_identity(rig):
    network, sim, drive = rig
    drive.sdo[0x1017].raw = 50
    drive.nmt.wait_for_heartbeat(1.0)
    assert drive.nmt.state == "PRE-OPERATIONAL"
    drive.nmt.state = "OPERATIONAL"
    time.sleep(0.12)
    assert drive.nmt.state == "OPERATIONAL"
    assert drive.sdo[0x1000].raw == drive.object_dictionary[0x1000].default
    assert drive.sdo[0x1018][1].raw == drive.object_dictionary[0x1018][1].default
    assert drive.sdo[0x1018][2].raw == drive.object_dictionary[0x1018][2].default


def test_expedited_and_segmented_sdo_and_abort_codes(rig):
    _, _, drive = rig
    assert drive.sdo[0x6065].raw == drive.object_dictionary[0x6065].default           # expedited
    name = drive.sdo[0x1008].raw                                                       # segmented upload
    assert len(name) > 4 and name == drive.object_dictionary[0x1008].default
    drive.sdo[0x6065].raw = 12345
    assert drive.sdo[0x6065].raw == 12345
    drive.sdo.download(0x6065, 0, (54321).to_bytes(4, "little"), force_segment=True)   # segmented download
    assert drive.sdo.upload(0x6065, 0) == (54321).to_bytes(4, "little")
    with pytest.raises(SdoAbortedError) as info:
        drive.sdo.upload(0x1234, 0)
    assert info.value.code == 0x06020000
    with pytest.raises(SdoAbortedError) as info:
        drive.sdo[0x6041].raw = 1
    assert info.value.code == 0x06010002
    with pytest.raises(SdoAbortedError) as info:
        drive.sdo[0x605A].raw = 99
    assert info.value.code == 0x06090031


def test_pdo_read_back_remap_and_sync_tpdos(rig):
    network, _, drive = rig
    drive.tpdo.read()
    assert [v.index for v in drive.tpdo[1].map] == [0x6041, 0x6064, 0x6061]
    assert drive.tpdo[4].enabled is False
    tpdo = drive.tpdo[4]                       # remap the unused TPDO4 to the following error
    tpdo.clear()
    tpdo.add_variable(0x60F4)
    tpdo.add_variable(0x6041)
    tpdo.trans_type = 1
    tpdo.enabled = True
    tpdo.save()
    drive.tpdo.read()
    assert [v.index for v in drive.tpdo[4].map] == [0x60F4, 0x6041] and drive.tpdo[4].enabled
    drive.nmt.state = "OPERATIONAL"
    time.sleep(0.05)
    network.sync.start(0.01)
    assert drive.tpdo[4].wait_for_reception(1.0) is not None      # every SYNC (transmission type 1)
    assert drive.tpdo[1].wait_for_reception(1.0) is not None
    assert drive.tpdo[4]["Statusword"].raw == drive.tpdo[1]["Statusword"].raw == 0x0640


def test_cia402_enable_move_and_emcy(rig):
    network, sim, drive = rig
    drive.setup_402_state_machine()
    drive.nmt.state = "OPERATIONAL"
    network.sync.start(0.01)
    time.sleep(0.05)
    start = drive.tpdo[1]["Position actual value"].raw
    drive.rpdo[1]["Target position"].raw = start
    drive.rpdo[1].start(0.01)                  # synchronous RPDO: the library sends it periodically
    drive.state = "OPERATION ENABLED"
    assert drive.state == "OPERATION ENABLED"
    goal = start + 200_000                      # increments (~0.012 rad at the joint)
    for k in range(1, 51):                     # CSP: a ramp of set-points, 10 ms apart
        drive.rpdo[1]["Target position"].raw = start + (goal - start) * k // 50
        time.sleep(0.01)
    time.sleep(0.2)
    assert abs(drive.tpdo[1]["Position actual value"].raw - goal) < 2000
    sim.node("joint_2").inject_fault(0x8611)
    emcy = drive.emcy.wait(0x8611, timeout=1.0)
    assert emcy is not None and emcy.code == 0x8611
    time.sleep(0.05)
    assert drive.state in ("FAULT", "FAULT REACTION ACTIVE")
