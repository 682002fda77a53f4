"""Bring-up of one node as its device description says (Lely's DCF-driven master, ros2_canopen's
per-node bus.yml): the EDS tells which objects exist and how they may be accessed; the master
configures only what exists.

- identity (1000h, 1018h.1/.2) read and compared with the EDS: a different device is refused;
- communication objects (1017h, 1016h, 1005h, 1006h) written only where they exist and differ
  from the value a reset-communication leaves (the EDS default); absent optional objects are
  skipped and listed in the report;
- fixed hardware data (608Fh, 6091h, 6076h for a drive) is written where the EDS says it is
  writable, otherwise read and used for scaling;
- the device's settings, a DCF's ParameterValue entries and the node's ``[sdo]`` table
  (in that order: the later wins), then the PDO layout: a PDO whose EDS
  default already is the configured layout is left alone, PDOs the configuration does not use
  are disabled only where the device has them and they are enabled by default.

Any refused write is a BootError naming the node, the object and the abort code.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Protocol

from spacearm.base.canopen import od
from spacearm.base.config.bus import BusSettings
from spacearm.base.canopen.codes import COB_ID_INVALID
from spacearm.drivers.devices import DeviceDriver
from spacearm.drivers.errors import BootError, DriverError
from spacearm.drivers.pdo_config import PdoSpec, find_var, pdo_count

logger = logging.getLogger(__name__)


class SdoAccess(Protocol):
    def sdo_read(self, node: str, index: int, subindex: int = 0): ...
    def sdo_write(self, node: str, index: int, subindex: int, value) -> None: ...


@dataclass
class BringupReport:
    """What bring-up did to one node (``status`` shows it)."""
    node: str
    sdo_writes: int = 0
    sdo_reads: int = 0
    skipped: list[str] = field(default_factory=list)       # optional objects the device lacks
    read_only: list[str] = field(default_factory=list)     # hardware data read instead of written
    guarding: str = ""
    node_guarding: bool = False    # the master polls the node (no heartbeat producer)


class NodeBringup:
    def __init__(self, net: SdoAccess, driver: DeviceDriver, bus: BusSettings):
        self.net, self.d, self.bus = net, driver, bus
        self.report = BringupReport(driver.name)

    # -- helpers -------------------------------------------------------------------
    def _var(self, index: int, sub: int):
        return find_var(self.d.od, index, sub)

    def _ref(self, index: int, sub: int) -> str:
        var = self._var(index, sub)
        return f"0x{index:04X}:{sub:02X}" + (f" '{var.name}'" if var is not None else "")

    def _write(self, index: int, sub: int, value) -> None:
        self.net.sdo_write(self.d.name, index, sub, value)
        self.report.sdo_writes += 1

    def _read(self, index: int, sub: int):
        self.report.sdo_reads += 1
        return self.net.sdo_read(self.d.name, index, sub)

    def _skip(self, index: int, sub: int, why: str) -> None:
        text = f"0x{index:04X}:{sub:02X} {why}"
        self.report.skipped.append(text)
        logger.info("%s: %s", self.d.label, text)

    def _write_if_present(self, index: int, sub: int, value, only_if_changed: bool) -> None:
        var = self._var(index, sub)
        if var is None:
            self._skip(index, sub, "not in the EDS (optional, skipped)")
        elif not var.writable:
            self._skip(index, sub, "read-only in the EDS (not written)")
        elif not (only_if_changed and var.default == value):
            self._write(index, sub, value)

    # -- steps ---------------------------------------------------------------------
    def run(self) -> BringupReport:
        try:
            self.check_identity()
            self.communication()
            self.hardware()
            for index, sub, value in self.d.config_writes():
                self._write_if_present(index, sub, value, only_if_changed=False)
            self.dcf_values()
            self.sdo_table()
            self.pdos()
        except BootError:
            raise
        except DriverError as exc:   # SdoError / SdoTimeoutError name node, object and code
            raise BootError(f"boot failed while configuring {exc}") from None
        return self.report

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
        if producer is None or not producer.writable:
            self._node_guarding()
            return
        self._write_if_present(od.PRODUCER_HEARTBEAT, 0, round(cfg.heartbeat_period * 1000), only_if_changed=True)
        consume = (b.master_node_id << 16) | round(b.master_heartbeat_timeout * 1000) \
            if b.master_heartbeat_period > 0 and b.master_heartbeat_timeout > 0 else 0
        if self._var(od.CONSUMER_HEARTBEAT, 1) is not None:
            self._write_if_present(od.CONSUMER_HEARTBEAT, 1, consume, only_if_changed=True)
            self.report.guarding = "heartbeat 1017h; the node consumes the master's heartbeat (1016h)"
        else:
            self._skip(od.CONSUMER_HEARTBEAT, 1, "not in the EDS: the node cannot watch the master")
            self.report.guarding = "heartbeat 1017h, watched by the master only (no 1016h)"
        self._write_if_present(od.COB_ID_SYNC, 0, od.SYNC_COB_ID_DEFAULT, only_if_changed=True)
        self._write_if_present(od.COMM_CYCLE_PERIOD, 0, round(b.sync_period * 1e6), only_if_changed=True)

    def _node_guarding(self) -> None:
        """A device with node guarding (100Ch/100Dh) but no heartbeat producer: the master
        polls it every heartbeat_period (RTR on 700h + ID) and the node watches the polls."""
        cfg = self.d.cfg
        guard, factor = self._var(od.GUARD_TIME, 0), self._var(od.LIFE_TIME_FACTOR, 0)
        if guard is None or factor is None or not guard.writable or not factor.writable:
            raise BootError(f"{self.d.label}: {cfg.eds_path.name} has neither a writable producer heartbeat "
                            f"time (1017h) nor node guarding (100Ch/100Dh): the node cannot be supervised")
        self._write(od.GUARD_TIME, 0, round(cfg.heartbeat_period * 1000))
        self._write(od.LIFE_TIME_FACTOR, 0, 3)
        self.report.guarding = (f"node guarding: the master polls every {cfg.heartbeat_period:g} s (100Ch/100Dh; "
                                f"no 1017h)")
        self.report.node_guarding = True
        self._write_if_present(od.COB_ID_SYNC, 0, od.SYNC_COB_ID_DEFAULT, only_if_changed=True)
        self._write_if_present(od.COMM_CYCLE_PERIOD, 0, round(self.bus.sync_period * 1e6), only_if_changed=True)

    def hardware(self) -> None:
        values: dict[tuple[int, int], int] = {}
        for index, sub, configured in self.d.hardware_objects():
            var = self._var(index, sub)
            if var is None:
                self._skip(index, sub, f"not in the EDS (the configured {configured} is used for scaling)")
            elif var.writable:
                self._write(index, sub, configured)
            else:
                values[(index, sub)] = actual = self._read(index, sub)
                self.report.read_only.append(f"0x{index:04X}:{sub:02X}={actual}")
                if actual != configured:
                    logger.info("%s: 0x%04X:%02X is %s on the device (configured %s): the device's value "
                                "is used", self.d.label, index, sub, actual, configured)
        self.d.use_hardware(values)

    def dcf_values(self) -> None:
        """A DCF's ParameterValue entries (as Lely's dcfgen), outside the PDO objects, whose
        layout comes from [nodes.pdo] or the EDS defaults."""
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
                self._write(index, var.subindex, value)

    def sdo_table(self) -> None:
        from spacearm.base.config.bus import parse_object_ref
        for ref, value in self.d.cfg.sdo.items():
            index, sub = parse_object_ref(ref)
            var = self._var(index, sub)
            if var is None or not var.writable:
                raise BootError(f"{self.d.label}: [sdo] {ref}: "
                                f"{'not in' if var is None else 'read-only in'} {self.d.cfg.eds_path.name}")
            self._write(index, sub, value)

    def pdos(self) -> None:
        for kind, comm, mapping, specs in (("RPDO", od.RPDO_COMM, od.RPDO_MAP, self.d.rpdos),
                                           ("TPDO", od.TPDO_COMM, od.TPDO_MAP, self.d.tpdos)):
            wanted = {s.number: s for s in specs}
            for n in range(pdo_count(self.d.od, comm)):
                self._pdo(kind, comm + n, mapping + n, wanted.get(n))

    def _pdo(self, kind: str, comm: int, mapping: int, spec: PdoSpec | None) -> None:
        cob_var = self._var(comm, od.PDO_COB_ID)
        if cob_var is None:
            raise BootError(f"{self.d.label}: {self._ref(comm, od.PDO_COB_ID)} missing in the EDS")
        default_cob = cob_var.default or 0
        if spec is None:                     # not used: disabled unless it already is
            if not default_cob & COB_ID_INVALID:
                self._write(comm, od.PDO_COB_ID, (default_cob & 0x7FF) | COB_ID_INVALID)
            return
        trans = self._var(comm, od.PDO_TRANSMISSION_TYPE)
        sync_needed = kind == "TPDO" and (trans is None or trans.default != od.TRANSMISSION_SYNC)
        if self._default_mapping(mapping) == [e.entry for e in spec.entries] \
                and default_cob == spec.cob_id and not sync_needed:
            return                           # a reset-communication leaves exactly this layout
        count = self._var(mapping, 0)
        if count is None or not count.writable:
            raise BootError(f"{self.d.label}: {spec.label}: the device's mapping is fixed "
                            f"({self._ref(mapping, 0)} is read-only) and differs from the configured one")
        self._write(comm, od.PDO_COB_ID, spec.cob_id | COB_ID_INVALID)
        self._write(mapping, 0, 0)
        for i, e in enumerate(spec.entries, start=1):
            self._write(mapping, i, e.entry)
        self._write(mapping, 0, len(spec.entries))
        if sync_needed:
            if trans is None or not trans.writable:
                raise BootError(f"{self.d.label}: {spec.label}: transmission type cannot be set to SYNC")
            self._write(comm, od.PDO_TRANSMISSION_TYPE, od.TRANSMISSION_SYNC)
        self._write(comm, od.PDO_COB_ID, spec.cob_id)

    def _default_mapping(self, mapping: int) -> list[int]:
        count = self._var(mapping, 0)
        n = count.default if count is not None and count.default else 0
        out = []
        for i in range(1, n + 1):
            var = self._var(mapping, i)
            out.append(var.default if var is not None and var.default else 0)
        return out
