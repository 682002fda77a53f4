"""Our master (spacearm.drivers.network.ArmNetwork) against each durand drive variant: one check
after the other on one virtual bus, each recorded pass/fail with what was seen. Used by
hil_tests/interop/test_master_vs_durand.py and bench/bench_bringup.py (the interop matrix).
"""
from __future__ import annotations

import math
import tempfile
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

from spacearm.base.config.bus import BusConfig, BusSettings, JointSettings, NodeConfig, PdoEntry, PdoLayout
from spacearm.drivers.errors import DriverError
from spacearm.drivers.network import ArmNetwork
from hil_tests.interop.durand_drive import HIGH_RPDO_COB, HIGH_TPDO_COB, VARIANTS, DurandDrive, Variant

CHECKS = ("boot", "enable", "csp_move", "restart", "emcy", "heartbeat_loss")
NODE_ID = 5         # where a variant does not say otherwise
MOVE = 0.3          # rad (m on a linear axis), the CSP move every drive must track


def layout(variant: Variant) -> PdoLayout:
    """What the bus file of this drive says: what the master needs, nothing vendor-specific."""
    if variant.high_pdos:
        return PdoLayout(rpdo=[PdoEntry(number=6, cob_id=HIGH_RPDO_COB, objects=["0x6040", "0x607A"])],
                         tpdo=[PdoEntry(number=7, cob_id=HIGH_TPDO_COB, objects=["0x6041", "0x6064", "0x6061"])])
    tpdo = [["0x6041", "0x6064", "0x6061"]]
    if variant.pdos[1] > 1:
        tpdo.append(["0x606C", "0x603F"])
    return PdoLayout(rpdo=[["0x6040", "0x607A"]], tpdo=tpdo)


def bus_config(variant: Variant, eds: Path, strict: bool = False) -> BusConfig:
    # a linear drive's bus file says a 10 mm lead: the drive's own read-only 6092h must win
    joint = JointSettings(feed_constant=0.01) if variant.feed is not None else None
    node = NodeConfig(name="joint_1", node_id=variant.node_id, device="joint_drive", heartbeat_period=0.1,
                      eds=str(eds), pdo=layout(variant), joint=joint, strict=strict)
    # node-ID 127 is the master's heartbeat by default: the master moves below it
    bus = BusSettings(master_node_id=126) if variant.node_id == 127 else BusSettings()
    return BusConfig(bus=bus, nodes=[node])


@dataclass
class Result:
    variant: str
    passed: dict[str, bool] = field(default_factory=dict)
    detail: dict[str, str] = field(default_factory=dict)
    sdo_writes: int = 0
    boot_time: float = 0.0
    skipped: list[str] = field(default_factory=list)

    def record(self, check: str, ok: bool, detail: str = "") -> bool:
        self.passed[check], self.detail[check] = bool(ok), detail
        return bool(ok)


def run_variant(name: str, workdir: Path | None = None) -> Result:
    variant = VARIANTS[name]
    result = Result(name)
    channel = f"durand-{name}-{uuid.uuid4().hex[:6]}"
    workdir = workdir or Path(tempfile.mkdtemp(prefix="durand-"))
    drive = DurandDrive(channel, variant.node_id, variant)
    net = ArmNetwork(f"virtual:{channel}",
                     bus_config(variant, drive.write_eds(workdir / f"durand_{name}.eds")))
    try:
        t0 = time.perf_counter()
        try:
            net.boot()
        except DriverError as exc:
            result.record("boot", False, str(exc))
            return result
        result.boot_time = time.perf_counter() - t0
        report = net.bringup["joint_1"]
        result.sdo_writes, result.skipped = report.sdo_writes, report.skipped
        result.record("boot", True, f"{report.sdo_writes} SDO writes, {len(report.skipped)} skipped")
        try:
            state = net.enable_all(max_cycles=20)
            result.record("enable", state.all_enabled, state.joints[0].state.value)
        except DriverError as exc:
            result.record("enable", False, str(exc))
            return result
        state = net.move_to([MOVE], 0.4)
        joint = net.joints[0]
        raw = net.sdo_read("joint_1", 0x6064, 0)
        travel, unit = (2 * math.pi, "rad") if variant.feed is None else (variant.feed * 1e-6, "m")
        expected_raw = round(MOVE * variant.encoder_increments * variant.gear / travel)
        ok = abs(state.joints[0].position - MOVE) < 1e-5 and abs(raw - expected_raw) <= 1
        result.record("csp_move", ok, f"{state.joints[0].position:.6f} {unit}, 6064h={raw} "
                                      f"(drive scaling {expected_raw}), k={joint.k:.1f}/{unit}")
        drive = _restart(net, drive, channel, variant, result)
        if drive is None:
            return result
        net.poll_events()
        drive.raise_fault(0x8611)
        for _ in range(3):
            state = net.cycle()
        events = [e for e in net.poll_events() if e.kind == "emcy"]
        result.record("emcy", any(e.code == 0x8611 for e in events) and state.joints[0].fault,
                      "; ".join(e.message for e in events) or "no EMCY event")
        drive.stop_heartbeat()
        deadline = time.monotonic() + 1.0
        lost = []
        while time.monotonic() < deadline and not lost:
            time.sleep(0.02)
            lost = [e for e in net.poll_events() if e.kind == "heartbeat_lost"]
        result.record("heartbeat_loss", bool(lost), lost[0].message if lost else "not detected in 1 s")
        return result
    finally:
        net.close()
        if drive is not None:
            drive.close()


def _restart(net: ArmNetwork, drive: DurandDrive, channel: str, variant: Variant,
             result: Result) -> DurandDrive | None:
    """Power cycle: a new drive on the bus, as it comes up (factory or stored state). The master
    must notice its boot-up, configure it again by itself and enable it; the PDO it then holds
    is read from the drive's own dictionary. None (recorded) if it did not."""
    net.poll_events()
    drive.close()
    drive = DurandDrive(channel, variant.node_id, variant)
    deadline, seen = time.monotonic() + 3.0, []
    while time.monotonic() < deadline and not {"reconfigured", "reconfigure_failed"} & {e.kind for e in seen}:
        time.sleep(0.02)
        seen += net.poll_events()
    kinds = [e.kind for e in seen]
    tpdo = net.drivers["joint_1"].tpdos[0]
    held = drive.held_pdo("TPDO", tpdo.number + 1)
    ok = "bootup" in kinds and "reconfigured" in kinds and held[0] == tpdo.cob_id \
        and held[2] == [e.entry for e in tpdo.entries]
    try:        # controlword by RPDO, statusword back by TPDO: process data both ways again
        ok = ok and net.enable_all(max_cycles=20).all_enabled
    except DriverError as exc:
        kinds.append(f"then: {exc}")
        ok = False
    result.record("restart", ok, f"events {kinds}; {tpdo.label} held 0x{held[0]:X} {[hex(e) for e in held[2]]}")
    if not ok:
        drive.close()
        return None
    return drive
