"""Bring-up of one node (the CiA 302-2 boot-slave process, as Lely's DCF-driven master does it):
the EDS tells which objects exist and how they may be accessed, the bus file what they should
hold; nothing is assumed about what the device holds now.

- identity (1000h, 1018h.1/.2) read and compared with the EDS: a different device is refused;
- verify configuration (1020h, where the EDS lists it): the master writes a stamp of the whole
  configuration there after a successful download and stores it (1010h); at the next boot a
  device that holds the same stamp is not configured again (skipped, ``report.verified``);
- otherwise every object is written explicitly: communication (1017h, 1016h, 1005h, 1006h),
  fixed hardware data (608Fh, 6091h, 6092h, 6076h for a drive: read instead where read-only),
  the device's settings, a DCF's ParameterValue entries, the node's ``[sdo]`` table, and every
  PDO the EDS lists: used ones disabled, mapped, given their transmission type and COB-ID, unused
  ones disabled; then the mapping and COB-ID of every used PDO are read back and compared.

A device that refuses an optional object (abort 0602 0000h or 0601 0002h: an EDS that
overstates it) gets a line in ``report.refused`` and the fallback is used (master-side
heartbeat supervision without 1016h, master-side following-error window without 6065h, the
device's own scaling read and used); mandatory objects, PDO configuration, the node's ``[sdo]``
table and, with ``strict = true``, every object stop the boot with a BootError naming the node,
the object and the abort code.
"""
from __future__ import annotations

import hashlib
import logging
from dataclasses import dataclass, field
from typing import Protocol

from spacearm.base.canopen import od
from spacearm.base.canopen.codes import ABORT_NO_OBJECT, ABORT_NO_SUBINDEX, ABORT_READ_ONLY, COB_ID_INVALID
from spacearm.base.config.bus import BusSettings, parse_object_ref
from spacearm.drivers.devices import DeviceDriver
from spacearm.drivers.errors import BootError, DriverError, SdoError
from spacearm.drivers.line_redundancy import redundancy_writes
from spacearm.drivers.pdo_config import PdoSpec, find_var, pdo_numbers

logger = logging.getLogger(__name__)

# What a device that lacks an object, or has it read-only, answers
REFUSALS = (ABORT_NO_OBJECT, ABORT_NO_SUBINDEX, ABORT_READ_ONLY)
# Objects CiA 301 / 402 make mandatory (for the services this master uses): never optional
MANDATORY = frozenset({od.DEVICE_TYPE, od.ERROR_REGISTER, od.IDENTITY, od.ERROR_CODE, od.CONTROLWORD,
                       od.STATUSWORD, od.MODES_OF_OPERATION, od.MODES_OF_OPERATION_DISPLAY})
# What the master does instead when the device refuses an optional object
FALLBACKS = {
    od.CONSUMER_HEARTBEAT: "the master alone supervises the node's heartbeat (the node cannot watch the master)",
    od.COMM_CYCLE_PERIOD: "the node is not told the SYNC period",
    od.COB_ID_SYNC: "the node keeps its own SYNC COB-ID",
    od.FOLLOWING_ERROR_WINDOW: "the master supervises the following error (window and timeout of the bus file)",
    od.FOLLOWING_ERROR_TIMEOUT: "the master supervises the following error (window and timeout of the bus file)",
    od.SOFTWARE_POSITION_LIMIT: "position limits are supervised by the controller only",
    od.MAX_TORQUE: "the drive keeps its own torque limit",
    od.INTERPOLATION_TIME_PERIOD: "the drive keeps its own interpolation period",
}
MASTER_FOLLOWING_ERROR = (od.FOLLOWING_ERROR_WINDOW, od.FOLLOWING_ERROR_TIMEOUT)


class SdoAccess(Protocol):
    def sdo_read(self, node: str, index: int, subindex: int = 0): ...
    def sdo_write(self, node: str, index: int, subindex: int, value) -> None: ...


@dataclass
class BringupReport:
    """What bring-up did to one node (``status`` shows it)."""
    node: str
    sdo_writes: int = 0
    sdo_reads: int = 0
    skipped: list[str] = field(default_factory=list)       # optional objects the EDS lacks
    refused: list[str] = field(default_factory=list)       # optional objects the device refused, with the fallback
    read_only: list[str] = field(default_factory=list)     # hardware data read instead of written
    guarding: str = ""
    node_guarding: bool = False    # the master polls the node (no heartbeat producer)
    master_following_error: bool = False   # the drive does not supervise it (no 6065h/6066h): the master does
    verified: bool = False         # 1020h matched: the device already held this configuration (nothing written)
    stored: str = ""               # what happened to the configuration afterwards (1020h/1010h)
    reboots: int = 0               # boot-ups during operation
    reboot: str = ""               # the last one and whether reconfiguration succeeded


def configuration_stamp(node_id: int, plan: list[tuple[int, int, int]]) -> tuple[int, int]:
    """The 1020h value of a configuration: CiA 302-2 puts the date (days since 1984) and time (ms
    after midnight) of the DCF there. This master has no DCF file date, so both are drawn from a
    digest of every write the configuration makes: the stamp changes exactly when it does."""
    digest = hashlib.blake2b(repr((node_id, plan)).encode(), digest_size=8).digest()
    high, low = int.from_bytes(digest[:4], "little"), int.from_bytes(digest[4:], "little")
    return high % 65536, low % 86_400_000


class NodeBringup:
    def __init__(self, net: SdoAccess, driver: DeviceDriver, bus: BusSettings):
        self.net, self.d, self.bus = net, driver, bus
        self.report = BringupReport(driver.name)
        self.planning = False
        self.plan: list[tuple[int, int, int]] = []

    # -- helpers -------------------------------------------------------------------
    def _var(self, index: int, sub: int):
        return find_var(self.d.od, index, sub)

    def _ref(self, index: int, sub: int) -> str:
        var = self._var(index, sub)
        return f"0x{index:04X}:{sub:02X}" + (f" '{var.name}'" if var is not None else "")

    def _write(self, index: int, sub: int, value, required: bool = False) -> bool:
        """One SDO write (recorded only, while planning). A refusal of an optional object is a
        report line and False; anything else raises."""
        if self.planning:
            self.plan.append((index, sub, value if isinstance(value, int) else repr(value)))
            return True
        try:
            self.net.sdo_write(self.d.name, index, sub, value)
        except SdoError as exc:
            if required or self.d.cfg.strict or exc.code not in REFUSALS or index in MANDATORY:
                raise
            self._refused(index, sub, exc, FALLBACKS.get(index, "not configured"))
            return False
        self.report.sdo_writes += 1
        return True

    def _refused(self, index: int, sub: int, exc: SdoError, fallback: str) -> None:
        text = f"0x{index:04X}:{sub:02X} refused by the device (0x{exc.code:08X} {exc.meaning}): {fallback}"
        self.report.refused.append(text)
        logger.warning("%s: %s", self.d.label, text)
        if index in MASTER_FOLLOWING_ERROR:
            self.report.master_following_error = True

    def _read(self, index: int, sub: int):
        self.report.sdo_reads += 1
        return self.net.sdo_read(self.d.name, index, sub)

    def _skip(self, index: int, sub: int, why: str) -> None:
        text = f"0x{index:04X}:{sub:02X} {why}"
        self.report.skipped.append(text)
        logger.info("%s: %s", self.d.label, text)
        if index in MASTER_FOLLOWING_ERROR:
            self.report.master_following_error = True

    def _write_if_present(self, index: int, sub: int, value) -> bool:
        var = self._var(index, sub)
        if var is None:
            self._skip(index, sub, "not in the EDS (optional, skipped)")
        elif not var.writable:
            self._skip(index, sub, "read-only in the EDS (not written)")
        else:
            return self._write(index, sub, value)
        return False

    # -- the boot-slave process ------------------------------------------------------
    def run(self) -> BringupReport:
        try:
            self.check_identity()
            verify = self._var(od.VERIFY_CONFIGURATION, 1) is not None \
                and self._var(od.VERIFY_CONFIGURATION, 2) is not None
            if verify:
                stamp = self._planned_stamp()
                if self._device_stamp() == stamp:
                    self.report.verified = True
                    self.report.stored = "1020h matches: configuration already on the device, not written"
                    return self.report
                self.report = BringupReport(self.d.name, sdo_reads=self.report.sdo_reads)
            self.configure()
            self.read_back()
            if verify:
                self.store(stamp)
        except BootError:
            raise
        except DriverError as exc:   # SdoError / SdoTimeoutError name node, object and code
            raise BootError(f"boot failed while configuring {exc}") from None
        return self.report

    def configure(self) -> None:
        self.communication()
        self.hardware()
        for index, sub, value in self.d.config_writes():
            self._write_if_present(index, sub, value)
        if getattr(self.net, "line_redundancy", None) is not None:     # on a redundant pair of lines
            for index, sub, value in redundancy_writes(self.net.config):
                if index in self.d.od:
                    self._write_if_present(index, sub, value)
        self.dcf_values()
        self.sdo_table()
        self.pdos()

    def _planned_stamp(self) -> tuple[int, int]:
        """Run the configuration without writing (reads of read-only data still happen: they
        decide the scaling) and stamp the writes it would make."""
        self.planning, self.plan = True, []
        try:
            self.configure()
        finally:
            self.planning = False
        return configuration_stamp(self.d.node_id, self.plan)

    def _device_stamp(self) -> tuple[int, int] | None:
        try:
            return self._read(od.VERIFY_CONFIGURATION, 1), self._read(od.VERIFY_CONFIGURATION, 2)
        except SdoError as exc:
            if self.d.cfg.strict or exc.code not in REFUSALS:
                raise
            self._refused(od.VERIFY_CONFIGURATION, 1, exc, "configured in full at every boot")
            return None

    def store(self, stamp: tuple[int, int]) -> None:
        """After a successful download: the stamp into 1020h, then everything stored (1010h)
        where the device can, so that its next boot restores this configuration. Only with
        1020h: storing at every boot would wear a device's flash for nothing."""
        if not (self._write(od.VERIFY_CONFIGURATION, 1, stamp[0]) and
                self._write(od.VERIFY_CONFIGURATION, 2, stamp[1])):
            self.report.stored = "1020h refused: configured in full at every boot"
            return
        store = self._var(od.STORE_PARAMETERS, 1)
        if store is None or not store.writable:
            self.report.stored = "1020h written; not stored (no writable 1010h:01): kept until power-off"
        elif self._write(od.STORE_PARAMETERS, 1, od.STORE_SIGNATURE):
            self.report.stored = "1020h written and stored (1010h:01)"
        else:
            self.report.stored = "1020h written; the store (1010h:01) was refused"

    def check_identity(self) -> None:
        eds = self.d.cfg.eds_path.name
        for index, sub in ((od.DEVICE_TYPE, 0), (od.IDENTITY, 1), (od.IDENTITY, 2)):
            var = self._var(index, sub)
            if var is None or var.default is None:
                raise BootError(f"{self.d.label}: the EDS {eds} has no value for {self._ref(index, sub)}")
            actual = self._read(index, sub)
            if actual != var.default:
                raise BootError(f"{self.d.label}: {var.name} (0x{index:04X}:{sub:02X}) is 0x{actual:08X}, "
                                f"the EDS {eds} expects 0x{var.default:08X} (wrong device or wrong EDS?)")

    def communication(self) -> None:
        b, cfg = self.bus, self.d.cfg
        producer = self._var(od.PRODUCER_HEARTBEAT, 0)
        if producer is None or not producer.writable or \
                not self._write(od.PRODUCER_HEARTBEAT, 0, round(cfg.heartbeat_period * 1000)):
            self._node_guarding()
            return
        consume = (b.master_node_id << 16) | round(b.master_heartbeat_timeout * 1000) \
            if b.master_heartbeat_period > 0 and b.master_heartbeat_timeout > 0 else 0
        if self._var(od.CONSUMER_HEARTBEAT, 1) is None:
            self._skip(od.CONSUMER_HEARTBEAT, 1, "not in the EDS: the node cannot watch the master")
            self.report.guarding = "heartbeat 1017h, watched by the master only (no 1016h)"
        elif self._write_if_present(od.CONSUMER_HEARTBEAT, 1, consume):
            self.report.guarding = "heartbeat 1017h; the node consumes the master's heartbeat (1016h)"
        else:
            self.report.guarding = "heartbeat 1017h, watched by the master only (1016h refused)"
        self._sync_objects()

    def _sync_objects(self) -> None:
        self._write_if_present(od.COB_ID_SYNC, 0, od.SYNC_COB_ID_DEFAULT)
        self._write_if_present(od.COMM_CYCLE_PERIOD, 0, round(self.bus.sync_period * 1e6))

    def _node_guarding(self) -> None:
        """A device with node guarding (100Ch/100Dh) but no (writable) heartbeat producer: the
        master polls it every heartbeat_period (RTR on 700h + ID) and the node watches the polls."""
        cfg = self.d.cfg
        guard, factor = self._var(od.GUARD_TIME, 0), self._var(od.LIFE_TIME_FACTOR, 0)
        if guard is None or factor is None or not guard.writable or not factor.writable:
            raise BootError(f"{self.d.label}: {cfg.eds_path.name} has neither a writable producer heartbeat "
                            f"time (1017h) nor node guarding (100Ch/100Dh): the node cannot be supervised")
        self._write(od.GUARD_TIME, 0, round(cfg.heartbeat_period * 1000), required=True)
        self._write(od.LIFE_TIME_FACTOR, 0, 3, required=True)
        self.report.guarding = (f"node guarding: the master polls every {cfg.heartbeat_period:g} s (100Ch/100Dh; "
                                f"no 1017h)")
        self.report.node_guarding = True
        self._sync_objects()

    def hardware(self) -> None:
        values: dict[tuple[int, int], int] = {}
        for index, sub, configured in self.d.hardware_objects():
            var = self._var(index, sub)
            if var is None:
                self._skip(index, sub, f"not in the EDS (the configured {configured} is used for scaling)")
                continue
            if var.writable and self._write(index, sub, configured):
                continue
            try:
                values[(index, sub)] = actual = self._read(index, sub)
            except SdoError as exc:
                if self.d.cfg.strict or exc.code not in REFUSALS:
                    raise
                self._refused(index, sub, exc, f"the configured {configured} is used for scaling")
                continue
            self.report.read_only.append(f"0x{index:04X}:{sub:02X}={actual}")
            if actual != configured:
                logger.info("%s: 0x%04X:%02X is %s on the device (configured %s): the device's value "
                            "is used", self.d.label, index, sub, actual, configured)
        self.d.use_hardware(values)

    def dcf_values(self) -> None:
        """A DCF's ParameterValue entries (as Lely's dcfgen), outside the PDO objects, whose
        layout comes from [nodes.pdo] or the EDS defaults. The user's own values: never optional."""
        for index in sorted(self.d.od.indices):
            if od.RPDO_COMM <= index < od.TPDO_MAP + 0x200:
                continue
            obj = self.d.od[index]
            variables = [obj] if not hasattr(obj, "subindices") else [obj[s] for s in sorted(obj.subindices)]
            for var in variables:
                value = getattr(var, "value", None)
                if value is None:
                    continue
                if not var.writable:
                    raise BootError(f"{self.d.label}: ParameterValue of {self._ref(index, var.subindex)} in "
                                    f"{self.d.cfg.eds_path.name}: the object is read-only")
                self._write(index, var.subindex, value, required=True)

    def sdo_table(self) -> None:
        for ref, value in self.d.cfg.sdo.items():
            index, sub = parse_object_ref(ref)
            var = self._var(index, sub)
            if var is None or not var.writable:
                raise BootError(f"{self.d.label}: [sdo] {ref}: "
                                f"{'not in' if var is None else 'read-only in'} {self.d.cfg.eds_path.name}")
            self._write(index, sub, value, required=True)

    # -- PDOs ------------------------------------------------------------------------
    def _directions(self):
        return (("RPDO", od.RPDO_COMM, od.RPDO_MAP, self.d.rpdos), ("TPDO", od.TPDO_COMM, od.TPDO_MAP, self.d.tpdos))

    def pdos(self) -> None:
        """Every PDO the EDS lists, whatever the device holds now: used ones written in full,
        the others disabled."""
        for kind, comm, mapping, specs in self._directions():
            wanted = {s.number: s for s in specs}
            for n in pdo_numbers(self.d.od, comm):
                spec = wanted.get(n)
                if spec is None:
                    self._disable_pdo(kind, n, comm + n)
                else:
                    self._pdo(kind, comm + n, mapping + n, spec)

    def _disable_pdo(self, kind: str, n: int, comm: int) -> None:
        cob_var = self._var(comm, od.PDO_COB_ID)
        if cob_var is None or not cob_var.writable:
            self._skip(comm, od.PDO_COB_ID, f"{kind}{n + 1} COB-ID not writable in the EDS: not disabled")
            return
        self._write(comm, od.PDO_COB_ID, ((cob_var.default or 0) & 0x7FF) | COB_ID_INVALID)

    def _pdo(self, kind: str, comm: int, mapping: int, spec: PdoSpec) -> None:
        for index, sub in ((comm, od.PDO_COB_ID), (mapping, 0)):
            var = self._var(index, sub)
            if var is None or not var.writable:
                raise BootError(f"{self.d.label}: {spec.label}: {self._ref(index, sub)} is "
                                f"{'missing' if var is None else 'read-only'} in the EDS: the PDO cannot be configured")
        self._write(comm, od.PDO_COB_ID, spec.cob_id | COB_ID_INVALID, required=True)
        self._write(mapping, 0, 0, required=True)
        for i, e in enumerate(spec.entries, start=1):
            self._write(mapping, i, e.entry, required=True)
        self._write(mapping, 0, len(spec.entries), required=True)
        trans = self._var(comm, od.PDO_TRANSMISSION_TYPE)
        if trans is not None and trans.writable:
            # both directions synchronous: TPDOs sent at every SYNC, RPDOs applied at the next one
            self._write(comm, od.PDO_TRANSMISSION_TYPE, od.TRANSMISSION_SYNC, required=True)
        elif kind == "TPDO" and (trans is None or trans.default != od.TRANSMISSION_SYNC):
            raise BootError(f"{self.d.label}: {spec.label}: transmission type cannot be set to SYNC")
        self._write(comm, od.PDO_COB_ID, spec.cob_id, required=True)

    def read_back(self) -> None:
        """Each used PDO's COB-ID and mapping as the device now holds them: a device that
        accepted a write and kept something else stops the boot here, not at the first SYNC."""
        for kind, comm, mapping, specs in self._directions():
            for spec in specs:
                cob = self._read(comm + spec.number, od.PDO_COB_ID)
                if cob & (COB_ID_INVALID | 0x7FF) != spec.cob_id:
                    raise BootError(f"{self.d.label}: {spec.label}: COB-ID read back 0x{cob:08X}, "
                                    f"written 0x{spec.cob_id:03X}")
                count = self._read(mapping + spec.number, 0)
                if count != len(spec.entries):
                    raise BootError(f"{self.d.label}: {spec.label}: {count} objects mapped on the device "
                                    f"(read back 0x{mapping + spec.number:04X}:00), {len(spec.entries)} written")
                for i, e in enumerate(spec.entries, start=1):
                    held = self._read(mapping + spec.number, i)
                    if held != e.entry:
                        raise BootError(f"{self.d.label}: {spec.label}: mapping entry {i} read back "
                                        f"0x{held:08X} (0x{mapping + spec.number:04X}:{i:02X}), "
                                        f"written 0x{e.entry:08X}")
