"""CiA 402 drives built on `durand` (PyPI), a CANopen responder stack nobody here wrote.

durand provides the CiA 301 side (NMT, SDO server, PDOs, SYNC consumer, EMCY and heartbeat
producers) and writes the device's EDS itself (``node.eds.content``); this module adds only a
small CiA 402 application (power state machine, cyclic synchronous position) and, for one
variant, a heartbeat consumer (1016h), so that the master is tried against:

    minimal       CiA 301 mandatory objects + the 402 objects its PDOs use, 4+4 PDOs
    ro_scaling    608Fh / 6091h / 6076h read-only, with values other than our bus file's
    exact_pdos    exactly one RPDO and one TPDO
    consumer      a 1016h heartbeat consumer (all the others have none)
    vendor_2000   vendor objects of its own at 2000h/2001h (not temperature/brake)
    linear_ro     a linear axis: 608Fh / 6091h / 6092h (feed constant) read-only, a lead other
                  than our bus file's
    stored_other  its EDS gives our layout as the default, but it holds another user's stored
                  mapping (RPDO1 entries swapped, TPDO1 position only and asynchronous, TPDO3 on)
    factory_empty its EDS gives our layout as the default, but it holds durand's factory state:
                  every mapping empty, transmission type 255
    overstated    its EDS (a vendor's) lists optional objects the drive lacks (1016h, 1006h,
                  6065h, 6066h, 6072h, 607Dh, 60C2h) or has read-only (608Fh, 6091h, 6076h)
    high_pdos     8+8 PDOs, node-ID 42; the bus file uses RPDO6 and TPDO7 on COB-IDs of its own
    verify        verify configuration (1020h) and store parameters (1010h)
    node_127      node-ID 127, the highest (the master's heartbeat moves to 126)

The 402 constants are written out here from the standard on purpose (not imported from
drivers/): the point is a second, independent reading of CiA 402.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from pathlib import Path

import can
from durand import CANBusNetwork, Node, Variable
from durand.datatypes import DatatypeEnum as DT
from durand.node import NodeCapabilities
from durand.object_dictionary import Array, Record
from durand.scheduler import SyncScheduler, set_scheduler

from spacearm.base.transport import open_bus

VENDOR_ID = 0x0000_0DDD          # made-up vendor of these test drives
PRODUCT_CODE = 0x0000_402D
DEVICE_TYPE_402 = 0x0002_0192    # CiA 402, servo drive, with the profile number in the low word

# CiA 402 statusword values (bit pattern of the power state machine) and controlword commands
SW_SWITCH_ON_DISABLED, SW_READY, SW_SWITCHED_ON, SW_OP_ENABLED = 0x0250, 0x0231, 0x0233, 0x0237
SW_QUICK_STOP, SW_FAULT = 0x0217, 0x0218


@dataclass(frozen=True)
class Variant:
    name: str
    ro_scaling: bool = False
    pdos: tuple[int, int] = (4, 4)      # (RPDOs, TPDOs) the device has
    consumer: bool = False
    vendor: bool = False
    encoder_increments: int = 1 << 20
    gear: int = 100
    feed: int | None = None             # 6092h.1 (um per shaft revolution): a linear axis
    node_id: int = 5
    eds_layout: bool = False            # the EDS gives the bus file's layout as its default ...
    holds: str = ""                     # ... while the drive holds "other" (a stored one) or "empty"
    overstated: bool = False
    high_pdos: bool = False             # the bus file maps RPDO6/TPDO7 on COB-IDs of its own
    verify: bool = False


# the layout our bus files give a drive (hil_tests/interop/matrix.py), as durand multiplexors
OUR_RPDO1 = ((0x6040, 0), (0x607A, 0))
OUR_TPDO1 = ((0x6041, 0), (0x6064, 0), (0x6061, 0))
OUR_TPDO2 = ((0x606C, 0), (0x603F, 0))
# optional objects a vendor EDS lists: absent from the drive / read-only on it
OVERSTATED_ABSENT = (0x1016, 0x1006, 0x6065, 0x6066, 0x6072, 0x607D, 0x60C2)
OVERSTATED_READ_ONLY = (0x608F, 0x6091, 0x6076)
HIGH_RPDO_COB, HIGH_TPDO_COB = 0x4E2, 0x3E1


VARIANTS = {
    "minimal": Variant("minimal"),
    # a different encoder and gear: positions only match if the master reads them
    "ro_scaling": Variant("ro_scaling", ro_scaling=True, encoder_increments=1 << 17, gear=160),
    "exact_pdos": Variant("exact_pdos", pdos=(1, 1)),
    "consumer": Variant("consumer", consumer=True),
    "vendor_2000": Variant("vendor_2000", vendor=True),
    # a 20 mm lead behind 1:1 and 10 000 increments: metres only match if the master reads 6092h
    "linear_ro": Variant("linear_ro", ro_scaling=True, encoder_increments=10_000, gear=1, feed=20_000),
    "stored_other": Variant("stored_other", eds_layout=True, holds="other"),
    "factory_empty": Variant("factory_empty", eds_layout=True, holds="empty"),
    # its own scaling too: positions only match if the master reads what it could not write
    "overstated": Variant("overstated", overstated=True, encoder_increments=1 << 17, gear=160),
    "high_pdos": Variant("high_pdos", pdos=(8, 8), node_id=42, high_pdos=True),
    "verify": Variant("verify", verify=True),
    "node_127": Variant("node_127", node_id=127),
}

_scheduler_lock = threading.Lock()
_scheduler: SyncScheduler | None = None


def _ensure_scheduler() -> None:
    """durand's timers (heartbeat, inhibit) need a scheduler; one thread for all drives."""
    global _scheduler
    with _scheduler_lock:
        if _scheduler is None:
            _scheduler = SyncScheduler()
            set_scheduler(_scheduler)
            threading.Thread(target=_scheduler.run, name="durand-scheduler", daemon=True).start()


class DurandDrive:
    """One durand node with a CSP drive application, on python-can's virtual bus."""

    def __init__(self, channel: str, node_id: int, variant: Variant):
        _ensure_scheduler()
        self.variant = variant
        # a bus spec (loopback:NAME, socketcan:vcan0) through our transports, else a virtual channel
        self.bus = open_bus(channel) if ":" in channel else \
            can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        self.network = CANBusNetwork(self.bus)
        rpdos, tpdos = variant.pdos
        self.node = Node(self.network, node_id, capabilities=NodeCapabilities(1, rpdos, tpdos))
        self.node_id = node_id
        od = self.od = self.node.object_dictionary
        od[0x1000] = Variable(DT.UNSIGNED32, "ro", DEVICE_TYPE_402, name="Device Type")
        od[0x1018][1] = Variable(DT.UNSIGNED32, "ro", VENDOR_ID, name="Vendor-ID")
        od[0x1018][2] = Variable(DT.UNSIGNED32, "ro", PRODUCT_CODE, name="Product Code")
        od[0x603F] = Variable(DT.UNSIGNED16, "ro", 0, name="Error code")
        od[0x6040] = Variable(DT.UNSIGNED16, "rw", 0, name="Controlword")
        od[0x6041] = Variable(DT.UNSIGNED16, "ro", SW_SWITCH_ON_DISABLED, name="Statusword")
        od[0x6060] = Variable(DT.INTEGER8, "rw", 8, name="Modes of operation")
        od[0x6061] = Variable(DT.INTEGER8, "ro", 8, name="Modes of operation display")
        od[0x6064] = Variable(DT.INTEGER32, "ro", 0, name="Position actual value")
        od[0x606C] = Variable(DT.INTEGER32, "ro", 0, name="Velocity actual value")
        od[0x607A] = Variable(DT.INTEGER32, "rw", 0, name="Target position")
        if variant.ro_scaling:
            enc = Array(Variable(DT.UNSIGNED32, "ro", 0), 2, name="Position encoder resolution")
            od[0x608F] = enc
            gear = Array(Variable(DT.UNSIGNED32, "ro", 0), 2, name="Gear ratio")
            od[0x6091] = gear
            od[0x6076] = Variable(DT.UNSIGNED32, "ro", 2000, name="Motor rated torque")
            scaling = [(0x608F, (variant.encoder_increments, 1)), (0x6091, (variant.gear, 1))]
            if variant.feed is not None:
                od[0x6092] = Array(Variable(DT.UNSIGNED32, "ro", 0), 2, name="Feed constant")
                scaling.append((0x6092, (variant.feed, 1)))
            for index, values in scaling:
                for sub, value in enumerate(values, start=1):
                    od.write(index, sub, value)
        if variant.vendor:
            od[0x2000] = Variable(DT.UNSIGNED32, "ro", 48000, name="DC link voltage mV")
            od[0x2001] = Variable(DT.UNSIGNED16, "rw", 0, name="Vendor tuning word")
        if variant.consumer:
            od[0x1016] = Array(Variable(DT.UNSIGNED32, "rw", 0, name="Consumer heartbeat time"), 1,
                               name="Consumer heartbeat time")
            od.write(0x1016, 1, 0)
            self._consumer_last: dict[int, float] = {}
        if variant.overstated:
            self._add_overstated_objects()
        if variant.verify:
            od[0x1020] = Array(Variable(DT.UNSIGNED32, "rw", 0, name="Verify configuration"), 2,
                               name="Verify configuration")
            od[0x1010] = Array(Variable(DT.UNSIGNED32, "rw", 1, name="Save all parameters"), 1,
                               name="Store parameters")
            self.stores = 0
            od.download_callbacks[(0x1010, 1)].add(self._on_store)
        if variant.eds_layout:
            self._hold_mapping(OUR_RPDO1, OUR_TPDO1, OUR_TPDO2, transmission=1)
        self.eds_text = self.node.eds.content    # the device description durand writes itself
        # what the drive holds from here on differs from what its EDS says
        if variant.overstated:
            self._withdraw_overstated_objects()
        if variant.holds == "other":
            self._hold_mapping(OUR_RPDO1[::-1], ((0x6064, 0),), (), transmission=255)
            self.node.tpdo[2].mapping = [(0x6041, 0)]
            self.node.tpdo[2].transmission_type = 255
        elif variant.holds == "empty":
            self._hold_mapping((), (), (), transmission=255)
        self.stalled = False
        self.state = "SWITCH_ON_DISABLED"
        self._last_cw = 0
        self.consumer_faults = 0
        self.node.sync.callbacks.add(self._on_sync)
        if variant.consumer:
            self.network.add_subscription(0x700 + 127, self._on_master_heartbeat)

    def _hold_mapping(self, rpdo1, tpdo1, tpdo2, transmission: int) -> None:
        self.node.rpdo[0].mapping = list(rpdo1)
        self.node.tpdo[0].mapping = list(tpdo1)
        self.node.tpdo[1].mapping = list(tpdo2)
        for pdo in (self.node.rpdo[0], self.node.tpdo[0], self.node.tpdo[1]):
            pdo.transmission_type = transmission

    def _add_overstated_objects(self) -> None:
        od = self.od
        od[0x1016] = Array(Variable(DT.UNSIGNED32, "rw", 0, name="Consumer heartbeat time"), 1,
                           name="Consumer heartbeat time")
        od[0x1006] = Variable(DT.UNSIGNED32, "rw", 0, name="Communication cycle period")
        od[0x6065] = Variable(DT.UNSIGNED32, "rw", 0, name="Following error window")
        od[0x6066] = Variable(DT.UNSIGNED16, "rw", 0, name="Following error time out")
        od[0x6072] = Variable(DT.UNSIGNED16, "rw", 1000, name="Max torque")
        od[0x607D] = Array(Variable(DT.INTEGER32, "rw", 0), 2, name="Software position limit")
        ipt = Record(name="Interpolation time period")
        ipt[1] = Variable(DT.UNSIGNED8, "rw", 1, name="Interpolation time period value")
        ipt[2] = Variable(DT.INTEGER8, "rw", -3, name="Interpolation time index")
        od[0x60C2] = ipt
        od[0x608F] = Array(Variable(DT.UNSIGNED32, "rw", 0), 2, name="Position encoder resolution")
        od[0x6091] = Array(Variable(DT.UNSIGNED32, "rw", 0), 2, name="Gear ratio")
        od[0x6076] = Variable(DT.UNSIGNED32, "rw", 2000, name="Motor rated torque")

    def _withdraw_overstated_objects(self) -> None:
        """The drive as it really is: durand's dictionary has no removal, so its two tables
        (variables, records/arrays) are edited directly; the scaling turns read-only with the
        drive's own values."""
        for index in OVERSTATED_ABSENT:
            self.od._variables.pop(index, None)
            self.od._objects.pop(index, None)
        self.od[0x608F] = Array(Variable(DT.UNSIGNED32, "ro", 0), 2, name="Position encoder resolution")
        self.od[0x6091] = Array(Variable(DT.UNSIGNED32, "ro", 0), 2, name="Gear ratio")
        self.od[0x6076] = Variable(DT.UNSIGNED32, "ro", 2000, name="Motor rated torque")
        for index, values in ((0x608F, (self.variant.encoder_increments, 1)), (0x6091, (self.variant.gear, 1))):
            for sub, value in enumerate(values, start=1):
                self.od.write(index, sub, value)

    def _on_store(self, value: int) -> None:
        if value == 0x65766173:    # "save"
            self.stores += 1

    # -- test hooks --------------------------------------------------------------
    def write_eds(self, path: Path) -> Path:
        path.write_text(self.eds_text)
        return path

    def raise_fault(self, code: int) -> None:
        """The drive detects an error: EMCY with this code, 402 state FAULT."""
        self.state = "FAULT"
        self.od.write(0x603F, 0, code)
        self.od.write(0x6041, 0, SW_FAULT)
        self.node.emcy.set(code, 0x01)

    def held_pdo(self, kind: str, number: int) -> tuple[int, int, list[int]]:
        """(COB-ID, transmission type, mapping entries) the drive holds for RPDO/TPDO `number`
        (1-based), read from its own dictionary."""
        comm, mapping = (0x1400, 0x1600) if kind == "RPDO" else (0x1800, 0x1A00)
        n = number - 1
        count = self.od.read(mapping + n, 0)
        return (self.od.read(comm + n, 1), self.od.read(comm + n, 2),
                [self.od.read(mapping + n, i) for i in range(1, count + 1)])

    def stop_heartbeat(self) -> None:
        self.od.write(0x1017, 0, 0)   # durand cancels its producer timer

    def close(self) -> None:
        self.od.write(0x1017, 0, 0)
        self.network.stop()
        self.bus.shutdown()

    # -- the drive's application ---------------------------------------------------
    def _on_master_heartbeat(self, cob_id: int, data: bytes) -> None:
        self._consumer_last[127] = time.monotonic()

    def _check_consumer(self) -> None:
        entry = self.od.read(0x1016, 1)
        producer, ms = (entry >> 16) & 0x7F, entry & 0xFFFF
        last = self._consumer_last.get(producer)
        if ms and last is not None and time.monotonic() - last > ms / 1000.0:
            del self._consumer_last[producer]
            self.consumer_faults += 1
            self.raise_fault(0x8130)

    def _on_sync(self) -> None:
        if self.variant.consumer:
            self._check_consumer()
        cw = self.od.read(0x6040, 0)
        rising_reset = cw & 0x80 and not self._last_cw & 0x80
        self._last_cw = cw
        s = self.state
        if s == "FAULT":
            if rising_reset:
                self.od.write(0x603F, 0, 0)
                self.node.emcy.set(0x0000, 0)
                s = "SWITCH_ON_DISABLED"
        elif not cw & 0x02:                                  # disable voltage
            s = "SWITCH_ON_DISABLED"
        elif not cw & 0x04:                                  # quick stop
            s = "QUICK_STOP" if s == "OPERATION_ENABLED" else "SWITCH_ON_DISABLED"
        elif cw & 0x0F == 0x06:                              # shutdown
            s = "READY_TO_SWITCH_ON"
        elif cw & 0x0F == 0x07 and s in ("READY_TO_SWITCH_ON", "OPERATION_ENABLED"):
            s = "SWITCHED_ON"
        elif cw & 0x0F == 0x0F and s in ("SWITCHED_ON", "OPERATION_ENABLED"):
            s = "OPERATION_ENABLED"
        self.state = s
        sw = {"SWITCH_ON_DISABLED": SW_SWITCH_ON_DISABLED, "READY_TO_SWITCH_ON": SW_READY,
              "SWITCHED_ON": SW_SWITCHED_ON, "OPERATION_ENABLED": SW_OP_ENABLED,
              "QUICK_STOP": SW_QUICK_STOP, "FAULT": SW_FAULT}[s]
        position = self.od.read(0x6064, 0)
        if s == "OPERATION_ENABLED" and not self.stalled:   # CSP: follow the target each SYNC
            target = self.od.read(0x607A, 0)
            self.od.write(0x606C, 0, target - position)
            position = target
        elif s != "OPERATION_ENABLED":
            self.od.write(0x607A, 0, position)
        self.od.write(0x6064, 0, position)
        self.od.write(0x6061, 0, self.od.read(0x6060, 0))
        self.od.write(0x6041, 0, sw)
