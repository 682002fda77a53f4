"""Simulated node conformance on the virtual bus: NMT, boot-up, SDO server and abort codes,
heartbeat, SYNC-driven TPDOs only in OPERATIONAL, EMCY, PDO mapping rules, bad frames."""
from __future__ import annotations

import struct
import time

import can
import canopen
import numpy as np
import pytest
from canopen.sdo.exceptions import SdoAbortedError

from spacearm.base.canopen import od, peer_timing
from spacearm.base.config.bus import EDS_DIR
from spacearm.base.transport import open_bus


@pytest.fixture
def raw(vbus):
    bus = open_bus(vbus)
    yield bus
    bus.shutdown()


@pytest.fixture
def client(vbus, sim):
    net = canopen.Network(open_bus(vbus))
    net.NOTIFIER_CYCLE = 0.05
    net.connect()
    node = net.add_node(1, str(EDS_DIR / "joint_drive.eds"))
    yield net, node
    net.disconnect()


def frames(bus: can.BusABC, duration: float) -> list[can.Message]:
    out, end = [], time.monotonic() + duration
    while time.monotonic() < end:
        msg = bus.recv(0.01)
        if msg is not None:
            out.append(msg)
    return out


def nmt(bus, command, node_id=0):
    bus.send(can.Message(arbitration_id=0, data=[command, node_id], is_extended_id=False))


def sync(bus):
    bus.send(can.Message(arbitration_id=0x80, data=[], is_extended_id=False))


def test_power_on_sends_bootup_for_every_node(vbus, bus_config):
    from spacearm.firmware_sim.runner import Simulator
    bus = open_bus(vbus)
    try:
        sim = Simulator(vbus, bus_config).start()
        got = frames(bus, 0.1)
        sim.stop()
    finally:
        bus.shutdown()
    bootups = sorted(m.arbitration_id - 0x700 for m in got if 0x700 < m.arbitration_id < 0x780 and list(m.data) == [0])
    assert bootups == sorted(n.node_id for n in bus_config.nodes)


def test_reset_communication_reboots_and_resets_comm_objects(client, raw):
    net, node = client
    node.sdo[od.PRODUCER_HEARTBEAT].raw = 30
    nmt(raw, od.NMT_RESET_COMMUNICATION, 1)
    got = frames(raw, 0.1)
    assert any(m.arbitration_id == 0x701 and list(m.data) == [0] for m in got)
    assert node.sdo[od.PRODUCER_HEARTBEAT].raw == 0


def test_heartbeat_period_and_nmt_states(client, raw):
    net, node = client
    node.sdo[od.PRODUCER_HEARTBEAT].raw = 20
    nmt(raw, od.NMT_START, 1)
    # the period from the frames' send times (median gap), not a count in a fixed window: a
    # timer thread the machine starved for a moment sends late, not at another period
    got = [m for m in frames(raw, 0.5) if m.arbitration_id == 0x701]
    gaps = np.diff([m.timestamp for m in got])
    assert len(got) >= 8 and 0.016 <= float(np.median(gaps)) <= 0.024, gaps
    assert got[-1].data[0] == od.NMT_STATE_OPERATIONAL
    nmt(raw, od.NMT_STOP, 1)
    got = [m for m in frames(raw, 0.1) if m.arbitration_id == 0x701]
    assert got[-1].data[0] == od.NMT_STATE_STOPPED
    with pytest.raises(canopen.SdoCommunicationError):   # no SDO in STOPPED
        node.sdo.upload(od.DEVICE_TYPE, 0)
    nmt(raw, od.NMT_PRE_OPERATIONAL, 1)
    got = [m for m in frames(raw, 0.1) if m.arbitration_id == 0x701]
    assert got[-1].data[0] == od.NMT_STATE_PRE_OPERATIONAL


def device_pdos(messages):
    """TPDOs of the bus config's devices: not the simulator's own timing report, an event-driven
    TPDO of its diagnostics node sent whenever its timer wakes late (base/canopen/peer_timing.py),
    whatever the devices' NMT states."""
    report = od.TPDO_BASE[0] + peer_timing.SIMULATOR_DIAG_NODE
    return [m for m in messages if 0x180 <= m.arbitration_id < 0x500 and m.arbitration_id != report]


def test_tpdos_on_sync_only_in_operational(sim, raw):
    sync(raw)
    assert not device_pdos(frames(raw, 0.05))
    nmt(raw, od.NMT_START)
    sync(raw)
    got = [m for m in frames(raw, 0.05) if 0x180 <= m.arbitration_id < 0x500]
    assert {m.arbitration_id for m in got} >= {0x181, 0x281, 0x381, 0x186, 0x190, 0x290, 0x191, 0x291}
    statusword, position, mode = struct.unpack("<HiB", next(m for m in got if m.arbitration_id == 0x181).data)
    assert statusword & 0x4F == 0x40 and mode == od.MODE_CSP    # switch on disabled, CSP
    nmt(raw, od.NMT_STOP)
    # The simulator answers frames in order on its own thread: once every node is STOPPED, the
    # answers to the SYNC before the stop are all on the bus (a loaded machine delivers them
    # later than the 50 ms window above), and only a TPDO sent on the next SYNC is a fault.
    deadline = time.monotonic() + 10.0
    while any(n.nmt_state != od.NMT_STATE_STOPPED for n in sim.nodes.values()) and time.monotonic() < deadline:
        time.sleep(0.005)
    frames(raw, 0.05)
    sync(raw)
    assert not device_pdos(frames(raw, 0.05))


def test_physics_advances_only_on_sync(sim, raw):
    plant = sim.plant
    t0, steps0 = plant.time, plant.steps
    time.sleep(0.1)
    assert plant.steps == steps0
    for _ in range(5):
        sync(raw)
    frames(raw, 0.05)
    assert plant.steps == steps0 + 5
    assert plant.time == pytest.approx(t0 + 5 * 0.02)


@pytest.mark.parametrize("index, sub, action, code", [
    (0x1234, 0, "read", 0x06020000),            # object does not exist
    (od.IDENTITY, 9, "read", 0x06090011),        # sub-index does not exist
    (od.STATUSWORD, 0, "write", 0x06010002),     # read only
    (od.DEVICE_TYPE, 0, "write", 0x06010002),
])
def test_sdo_abort_codes(client, index, sub, action, code):
    net, node = client
    with pytest.raises(SdoAbortedError) as info:
        if action == "read":
            node.sdo.upload(index, sub)
        else:
            node.sdo.download(index, sub, b"\x00\x00")
    assert info.value.code == code


def test_sdo_wrong_size_and_value_range(client):
    net, node = client
    with pytest.raises(SdoAbortedError) as info:
        node.sdo.download(od.CONTROLWORD, 0, b"\x01\x02\x03\x04")
    assert info.value.code == 0x06070012
    with pytest.raises(SdoAbortedError) as info:
        node.sdo.download(od.TARGET_POSITION, 0, b"\x01")
    assert info.value.code == 0x06070013
    with pytest.raises(SdoAbortedError) as info:
        node.sdo.download(od.QUICK_STOP_OPTION, 0, struct.pack("<h", 9))
    assert info.value.code == 0x06090031
    with pytest.raises(SdoAbortedError) as info:           # unsupported mode of operation
        node.sdo.download(od.MODES_OF_OPERATION, 0, struct.pack("<b", 3))
    assert info.value.code == 0x06090030


def test_sdo_segmented_upload_and_download(client):
    net, node = client
    assert node.sdo.upload(od.DEVICE_NAME, 0) == b"SpaceArm joint drive (sim)"     # segmented
    node.sdo.download(od.TARGET_POSITION, 0, struct.pack("<i", -123456), force_segment=True)
    assert struct.unpack("<i", node.sdo.upload(od.TARGET_POSITION, 0))[0] == -123456


def test_pdo_mapping_rules(client):
    net, node = client
    with pytest.raises(SdoAbortedError) as info:     # mapping change while the PDO is valid
        node.sdo.download(od.TPDO_MAP, 1, struct.pack("<I", (od.STATUSWORD << 16) | 16))
    assert info.value.code == 0x08000022
    node.sdo.download(od.TPDO_COMM, 1, struct.pack("<I", 0x80000181))
    with pytest.raises(SdoAbortedError) as info:     # not mappable
        node.sdo.download(od.TPDO_MAP, 1, struct.pack("<I", (od.MOTOR_RATED_TORQUE << 16) | 32))
    assert info.value.code == 0x06040041
    with pytest.raises(SdoAbortedError) as info:     # control word is not readable-only but RPDO-side...
        node.sdo.download(od.RPDO_COMM, 1, struct.pack("<I", 0x80000201)) or \
            node.sdo.download(od.RPDO_MAP, 1, struct.pack("<I", (od.STATUSWORD << 16) | 16))
    assert info.value.code == 0x06040041                # read-only object in an RPDO


def test_emcy_updates_error_register_and_history(sim, client, raw):
    net, node = client
    sim.node(1).inject_fault(od.EMCY_OVER_TEMPERATURE_DRIVE, od.ERR_REG_TEMPERATURE)
    got = [m for m in frames(raw, 0.05) if m.arbitration_id == 0x81]
    code, register, _ = struct.unpack("<HB5s", got[0].data)
    assert code == od.EMCY_OVER_TEMPERATURE_DRIVE and register & (od.ERR_REG_GENERIC | od.ERR_REG_TEMPERATURE)
    assert node.sdo[od.ERROR_REGISTER].raw == register
    assert node.sdo[od.PREDEFINED_ERROR_FIELD][0].raw == 1
    assert node.sdo[od.PREDEFINED_ERROR_FIELD][1].raw == od.EMCY_OVER_TEMPERATURE_DRIVE
    node.sdo[od.PREDEFINED_ERROR_FIELD][0].raw = 0              # clears the history
    assert node.sdo[od.PREDEFINED_ERROR_FIELD][1].raw == 0


def test_malformed_and_unknown_frames_are_counted_never_fatal(sim, client, raw):
    net, node = client
    bad = [
        can.Message(arbitration_id=0x601, data=[0x40, 0x00], is_extended_id=False),        # SDO DLC 2
        can.Message(arbitration_id=0x000, data=[0x01], is_extended_id=False),              # NMT DLC 1
        can.Message(arbitration_id=0x000, data=[0x77, 0x01], is_extended_id=False),        # unknown NMT cmd
        can.Message(arbitration_id=0x080, data=[1, 2, 3], is_extended_id=False),           # SYNC DLC 3
        can.Message(arbitration_id=0x6FF, data=[0] * 8, is_extended_id=False),             # SDO to no node
        can.Message(arbitration_id=0x123, data=[1, 2], is_extended_id=False),              # unknown
        can.Message(arbitration_id=0x601, data=[0x40, 0, 0x10, 0, 0, 0, 0, 0], is_extended_id=True),
        can.Message(arbitration_id=0x601, is_remote_frame=True, is_extended_id=False),
        can.Message(arbitration_id=0x601, data=[0xFF] * 8, is_extended_id=False),          # bad command
    ]
    for msg in bad:
        raw.send(msg)
    frames(raw, 0.05)
    assert sim.stats.malformed == 2
    assert sim.stats.unknown == 2
    assert sim.stats.ignored == 2
    assert sim.node(1).stats.malformed >= 2
    assert sim.stats.internal_errors == 0
    assert node.sdo[od.DEVICE_TYPE].raw == 0x00020192          # still serving
    nmt(raw, od.NMT_START)
    raw.send(can.Message(arbitration_id=0x201, data=[0x06], is_extended_id=False))   # short RPDO
    got = [m for m in frames(raw, 0.05) if m.arbitration_id == 0x81]
    assert got and struct.unpack_from("<H", got[0].data)[0] == od.EMCY_PDO_LENGTH


def test_sdo_abort_injection(sim, client):
    net, node = client
    sim.node(1).faults.sdo_abort = 0x08000020
    with pytest.raises(SdoAbortedError) as info:
        node.sdo.upload(od.DEVICE_TYPE, 0)
    assert info.value.code == 0x08000020
    sim.node(1).faults.sdo_abort = None
    assert node.sdo[od.DEVICE_TYPE].raw == 0x00020192
