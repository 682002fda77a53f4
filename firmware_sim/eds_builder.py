"""Generates configs/eds/*.eds from the object list below (indices from spacearm.base.canopen.od).

The EDS files are the source of truth the simulator and the controller both load; this
module only exists so they stay consistent and complete. Regenerate with

    .venv/bin/python -m spacearm.firmware_sim.eds_builder

and commit the result (tests/canopen/test_eds.py checks the files are up to date).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from spacearm.base.paths import CONFIGS
from spacearm.base.canopen import od
from spacearm.base.canopen import redundancy_object as rdn
from spacearm.base.canopen.pdo_maps import PDO_MAPS

EDS_DIR = CONFIGS / "eds"

from spacearm.base.canopen.codes import (BOOLEAN, INTEGER8, INTEGER16, INTEGER32, UNSIGNED8,  # noqa: E402,F401
                                   UNSIGNED16, UNSIGNED32, VISIBLE_STRING)
from spacearm.base.canopen.codes import OBJECT_ARRAY as ARRAY, OBJECT_RECORD as RECORD, OBJECT_VAR as VAR  # noqa: E402

VENDOR_ID = 0x0000_05A7  # simulated vendor ("SpaceArm sim"); not a registered CiA ID


@dataclass
class Var:
    name: str
    data_type: int
    access: str = "rw"
    default: str | int | None = 0
    pdo: bool = False
    low: int | None = None
    high: int | None = None


@dataclass
class Obj:
    index: int
    name: str
    kind: int = VAR
    var: Var | None = None                      # for VAR
    subs: dict[int, Var] = field(default_factory=dict)  # for ARRAY/RECORD (sub 0 added)


def v(index, name, dt, access="rw", default=0, pdo=False, low=None, high=None) -> Obj:
    return Obj(index, name, VAR, Var(name, dt, access, default, pdo, low, high))


def comm_objects(device_type: int, product: int, name: str, consumer_heartbeat: bool = True) -> list[Obj]:
    objs = [
        v(od.DEVICE_TYPE, "Device type", UNSIGNED32, "ro", device_type),
        v(od.ERROR_REGISTER, "Error register", UNSIGNED8, "ro", 0, pdo=True),
        Obj(od.PREDEFINED_ERROR_FIELD, "Pre-defined error field", ARRAY,
            subs={0: Var("Number of errors", UNSIGNED8, "rw", 0, high=8),
                  **{i: Var(f"Standard error field {i}", UNSIGNED32, "ro", 0) for i in range(1, 9)}}),
        v(od.COB_ID_SYNC, "COB-ID SYNC", UNSIGNED32, "rw", od.SYNC_COB_ID_DEFAULT),
        v(od.COMM_CYCLE_PERIOD, "Communication cycle period", UNSIGNED32, "rw", 0),
        v(od.DEVICE_NAME, "Manufacturer device name", VISIBLE_STRING, "const", name),
        v(od.HW_VERSION, "Manufacturer hardware version", VISIBLE_STRING, "const", "SIM-1"),
        v(od.SW_VERSION, "Manufacturer software version", VISIBLE_STRING, "const", "spacearm-fw-sim 0.1"),
        v(od.COB_ID_EMCY, "COB-ID EMCY", UNSIGNED32, "rw", "$NODEID+0x80"),
        Obj(od.CONSUMER_HEARTBEAT, "Consumer heartbeat time", ARRAY,
            subs={0: Var("Number of entries", UNSIGNED8, "ro", 4),
                  **{i: Var(f"Consumer heartbeat time {i}", UNSIGNED32, "rw", 0) for i in range(1, 5)}}),
        v(od.PRODUCER_HEARTBEAT, "Producer heartbeat time", UNSIGNED16, "rw", 0),
        Obj(od.IDENTITY, "Identity object", RECORD,
            subs={0: Var("Number of entries", UNSIGNED8, "ro", 4),
                  1: Var("Vendor-ID", UNSIGNED32, "ro", VENDOR_ID),
                  2: Var("Product code", UNSIGNED32, "ro", product),
                  3: Var("Revision number", UNSIGNED32, "ro", 0x0001_0000),
                  4: Var("Serial number", UNSIGNED32, "ro", 0)}),
    ]
    if not consumer_heartbeat:
        objs = [o for o in objs if o.index != od.CONSUMER_HEARTBEAT]
    else:    # the slave's bus redundancy rule needs the master's heartbeat (1016h:1)
        objs.append(redundancy_object())
    return objs


def redundancy_object() -> Obj:
    """ECSS-E-ST-50-15C bus redundancy, as Lely's redundancy object (base/canopen/redundancy_object.py)."""
    return Obj(rdn.REDUNDANCY, "Bus redundancy", RECORD, subs={
        0: Var("Highest sub-index supported", UNSIGNED8, "ro", 4),
        rdn.BDEFAULT: Var("Bdefault", UNSIGNED8, "rw", rdn.DEFAULTS[rdn.BDEFAULT], high=1),
        rdn.TTOGGLE: Var("Ttoggle", UNSIGNED8, "rw", rdn.DEFAULTS[rdn.TTOGGLE]),
        rdn.NTOGGLE: Var("Ntoggle", UNSIGNED8, "rw", rdn.DEFAULTS[rdn.NTOGGLE], low=1),
        rdn.CTOGGLE: Var("Ctoggle", UNSIGNED8, "rw", rdn.DEFAULTS[rdn.CTOGGLE])})


def pdo_objects(rpdo_maps: list[list[tuple[int, int, int]]], tpdo_maps: list[list[tuple[int, int, int]]],
                counts: tuple[int, int] = (od.N_PDOS, od.N_PDOS)) -> list[Obj]:
    """counts = (RPDOs, TPDOs) the device has (four each by default); the given default
    mappings are (index, sub, bits)."""
    objs: list[Obj] = []
    for kind, comm, mapi, bases, maps, count in (
            ("RPDO", od.RPDO_COMM, od.RPDO_MAP, od.RPDO_BASE, rpdo_maps, counts[0]),
            ("TPDO", od.TPDO_COMM, od.TPDO_MAP, od.TPDO_BASE, tpdo_maps, counts[1])):
        for n in range(count):
            mapping = maps[n] if n < len(maps) else []
            # unmapped PDOs start disabled (bit 31 set)
            cob = f"$NODEID+0x{bases[n] if mapping else od.PDO_COB_ID_INVALID + bases[n]:X}"
            subs = {0: Var("Highest sub-index supported", UNSIGNED8, "ro", 6 if kind == "TPDO" else 2),
                    od.PDO_COB_ID: Var(f"COB-ID used by {kind}", UNSIGNED32, "rw", cob),
                    od.PDO_TRANSMISSION_TYPE: Var("Transmission type", UNSIGNED8, "rw", od.TRANSMISSION_SYNC)}
            if kind == "TPDO":
                subs[od.PDO_INHIBIT_TIME] = Var("Inhibit time", UNSIGNED16, "rw", 0)
                subs[od.PDO_EVENT_TIMER] = Var("Event timer", UNSIGNED16, "rw", 0)
                subs[od.PDO_SYNC_START] = Var("SYNC start value", UNSIGNED8, "rw", 0)
            objs.append(Obj(comm + n, f"{kind} communication parameter {n + 1}", RECORD, subs=subs))
            msubs = {0: Var("Number of mapped objects", UNSIGNED8, "rw", len(mapping), high=od.MAX_MAPPED)}
            for i in range(1, od.MAX_MAPPED + 1):
                value = 0
                if i <= len(mapping):
                    idx, sub, bits = mapping[i - 1]
                    value = (idx << 16) | (sub << 8) | bits
                msubs[i] = Var(f"Mapped object {i}", UNSIGNED32, "rw", f"0x{value:08X}")
            objs.append(Obj(mapi + n, f"{kind} mapping parameter {n + 1}", RECORD, subs=msubs))
    return objs


# Default PDO mappings = what the controller configures at bring-up (base/canopen/pdo_maps.py).
JOINT_RPDOS, JOINT_TPDOS = PDO_MAPS["joint_drive"]["rpdo"], PDO_MAPS["joint_drive"]["tpdo"]
EE_RPDOS, EE_TPDOS = PDO_MAPS["end_effector"]["rpdo"], PDO_MAPS["end_effector"]["tpdo"]
FT_RPDOS, FT_TPDOS = PDO_MAPS["ft_sensor"]["rpdo"], PDO_MAPS["ft_sensor"]["tpdo"]


def joint_drive() -> tuple[str, list[Obj]]:
    objs = comm_objects(0x0002_0192, 0x0402_0001, "SpaceArm joint drive (sim)")
    objs += pdo_objects(JOINT_RPDOS, JOINT_TPDOS)
    objs += drive_objects(scaling_access="rw", encoder=1 << 20, gear=100, rated_torque=1500)
    return "SpaceArm joint drive (CiA 402: CSP, PP)", objs


# The second drive model: a smaller wrist drive of another make. One RPDO and two TPDOs, no
# heartbeat consumer (1016h), an encoder of 2^17 increments behind a 160:1 gear, and its
# hardware data (608Fh, 6091h, 6092h, 6076h) read-only; its default TPDO2 maps its own temperature.
COMPACT_RPDOS = [[(od.CONTROLWORD, 0, 16), (od.TARGET_POSITION, 0, 32)]]
COMPACT_TPDOS = [[(od.STATUSWORD, 0, 16), (od.POSITION_ACTUAL, 0, 32), (od.MODES_OF_OPERATION_DISPLAY, 0, 8)],
                 [(od.VELOCITY_ACTUAL, 0, 32), (od.TORQUE_ACTUAL, 0, 16), (od.DRIVE_TEMPERATURE, 0, 16)]]


def joint_drive_compact() -> tuple[str, list[Obj]]:
    objs = comm_objects(0x0002_0192, 0x0402_0C01, "SpaceArm compact wrist drive (sim)", consumer_heartbeat=False)
    objs += pdo_objects(COMPACT_RPDOS, COMPACT_TPDOS, counts=(1, 2))
    objs += drive_objects(scaling_access="ro", encoder=1 << 17, gear=160, rated_torque=600)
    return "SpaceArm compact wrist drive (CiA 402: CSP, PP; 1 RPDO, 2 TPDOs)", objs


def drive_objects(scaling_access: str, encoder: int, gear: int, rated_torque: int) -> list[Obj]:
    """The CiA 402 objects of a joint drive (and its two manufacturer objects)."""
    return [
        v(od.DRIVE_TEMPERATURE, "Drive temperature", INTEGER16, "ro", 250, pdo=True),
        v(od.BRAKE_STATUS, "Brake status", UNSIGNED8, "ro", 1, pdo=True),
        v(od.ERROR_CODE, "Error code", UNSIGNED16, "ro", 0, pdo=True),
        v(od.CONTROLWORD, "Controlword", UNSIGNED16, "rw", 0, pdo=True),
        v(od.STATUSWORD, "Statusword", UNSIGNED16, "ro", 0, pdo=True),
        v(od.QUICK_STOP_OPTION, "Quick stop option code", INTEGER16, "rw", 2, low=0, high=8),
        v(od.FAULT_REACTION_OPTION, "Fault reaction option code", INTEGER16, "rw", 2, low=0, high=2),
        v(od.MODES_OF_OPERATION, "Modes of operation", INTEGER8, "rw", od.MODE_CSP, pdo=True),
        v(od.MODES_OF_OPERATION_DISPLAY, "Modes of operation display", INTEGER8, "ro", od.MODE_CSP, pdo=True),
        v(od.POSITION_DEMAND, "Position demand value", INTEGER32, "ro", 0, pdo=True),
        v(od.POSITION_ACTUAL, "Position actual value", INTEGER32, "ro", 0, pdo=True),
        v(od.FOLLOWING_ERROR_WINDOW, "Following error window", UNSIGNED32, "rw", 166886),
        v(od.FOLLOWING_ERROR_TIMEOUT, "Following error time out", UNSIGNED16, "rw", 100),
        v(od.POSITION_WINDOW, "Position window", UNSIGNED32, "rw", 1669),
        v(od.VELOCITY_ACTUAL, "Velocity actual value", INTEGER32, "ro", 0, pdo=True),
        v(od.TARGET_TORQUE, "Target torque", INTEGER16, "rw", 0, pdo=True),
        v(od.MAX_TORQUE, "Max torque", UNSIGNED16, "rw", 1000, pdo=True),
        v(od.MOTOR_RATED_TORQUE, "Motor rated torque", UNSIGNED32, scaling_access, rated_torque),
        v(od.TORQUE_ACTUAL, "Torque actual value", INTEGER16, "ro", 0, pdo=True),
        v(od.TARGET_POSITION, "Target position", INTEGER32, "rw", 0, pdo=True),
        Obj(od.SOFTWARE_POSITION_LIMIT, "Software position limit", ARRAY,
            subs={0: Var("Number of entries", UNSIGNED8, "ro", 2),
                  1: Var("Min position limit", INTEGER32, "rw", -2**31),
                  2: Var("Max position limit", INTEGER32, "rw", 2**31 - 1)}),
        v(od.MAX_PROFILE_VELOCITY, "Max profile velocity", UNSIGNED32, "rw", 16_688_000),
        v(od.PROFILE_VELOCITY, "Profile velocity", UNSIGNED32, "rw", 1_668_860),
        v(od.PROFILE_ACCELERATION, "Profile acceleration", UNSIGNED32, "rw", 3_337_720),
        v(od.PROFILE_DECELERATION, "Profile deceleration", UNSIGNED32, "rw", 3_337_720),
        v(od.QUICK_STOP_DECELERATION, "Quick stop deceleration", UNSIGNED32, "rw", 16_688_600),
        Obj(od.POSITION_ENCODER_RESOLUTION, "Position encoder resolution", ARRAY,
            subs={0: Var("Number of entries", UNSIGNED8, "ro", 2),
                  1: Var("Encoder increments", UNSIGNED32, scaling_access, encoder, low=1),
                  2: Var("Motor revolutions", UNSIGNED32, scaling_access, 1, low=1)}),
        Obj(od.GEAR_RATIO, "Gear ratio", ARRAY,
            subs={0: Var("Number of entries", UNSIGNED8, "ro", 2),
                  1: Var("Motor revolutions", UNSIGNED32, scaling_access, gear, low=1),
                  2: Var("Shaft revolutions", UNSIGNED32, scaling_access, 1, low=1)}),
        # 6092h: travel per shaft revolution of a linear axis (feed in um, axis_scale.py); a
        # rotary axis does not use it. Default: a 5 mm lead screw.
        Obj(od.FEED_CONSTANT, "Feed constant", ARRAY,
            subs={0: Var("Number of entries", UNSIGNED8, "ro", 2),
                  1: Var("Feed", UNSIGNED32, scaling_access, 5_000, low=1),
                  2: Var("Shaft revolutions", UNSIGNED32, scaling_access, 1, low=1)}),
        v(od.VELOCITY_OFFSET, "Velocity offset", INTEGER32, "rw", 0, pdo=True),
        v(od.TORQUE_OFFSET, "Torque offset", INTEGER16, "rw", 0, pdo=True),
        Obj(od.INTERPOLATION_TIME_PERIOD, "Interpolation time period", RECORD,
            subs={0: Var("Highest sub-index supported", UNSIGNED8, "ro", 2),
                  1: Var("Interpolation time period value", UNSIGNED8, "rw", 20),
                  2: Var("Interpolation time index", INTEGER8, "rw", -3, low=-128, high=63)}),
        v(od.FOLLOWING_ERROR_ACTUAL, "Following error actual value", INTEGER32, "ro", 0, pdo=True),
        v(od.SUPPORTED_DRIVE_MODES, "Supported drive modes", UNSIGNED32, "ro", 0x81),
    ]


def end_effector() -> tuple[str, list[Obj]]:
    objs = comm_objects(0x0000_0000, 0x0EE0_0001, "SpaceArm end-effector controller (sim)")
    objs += pdo_objects(EE_RPDOS, EE_TPDOS)
    objs += [
        v(od.EE_COMMAND, "End-effector command", UNSIGNED8, "rw", 0, pdo=True, high=max(od.EeCommand)),
        v(od.EE_STATE, "End-effector state", UNSIGNED8, "ro", 1, pdo=True),
        v(od.EE_SCREW_TORQUE, "Screw torque", INTEGER16, "ro", 0, pdo=True),
        v(od.EE_SCREW_TURNS, "Screw turns", INTEGER32, "ro", 0, pdo=True),
        v(od.EE_GRIP_POSITION, "Grip position", UNSIGNED16, "ro", 0, pdo=True),
        v(od.EE_FAULT_CODE, "End-effector fault code", UNSIGNED16, "ro", 0, pdo=True),
        v(od.EE_SCREW_TORQUE_LIMIT, "Screw lock torque", UNSIGNED16, "rw", 8000, low=100, high=30000),
        v(od.EE_LOCK_TURNS, "Screw turns to lock", UNSIGNED32, "rw", 6000, low=100, high=100000),
    ]
    return "SpaceArm end-effector controller (clamp/release, screw)", objs


def ft_sensor() -> tuple[str, list[Obj]]:
    # device type 0: no standard device profile (its objects are manufacturer specific, not CiA 404's)
    objs = comm_objects(0x0000_0000, 0x0F70_0001, "SpaceArm 6-axis F/T sensor (sim)")
    objs += pdo_objects(FT_RPDOS, FT_TPDOS)
    names = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")
    objs += [
        Obj(od.FT_VALUES, "Force torque values", ARRAY,
            subs={0: Var("Number of entries", UNSIGNED8, "ro", 6),
                  **{i + 1: Var(n, INTEGER16, "ro", 0, pdo=True) for i, n in enumerate(names)}}),
        v(od.FT_FORCE_COUNTS_PER_N, "Force counts per N", UNSIGNED32, "rw", 100, low=1),
        v(od.FT_TORQUE_COUNTS_PER_NM, "Torque counts per N m", UNSIGNED32, "rw", 1000, low=1),
        v(od.FT_STATUS, "Sensor status", UNSIGNED8, "ro", 0, pdo=True),
        v(od.FT_TARE, "Tare command", UNSIGNED8, "rw", 0, pdo=True, high=2),
        Obj(od.FT_OVERLOAD_LIMIT, "Overload limit", ARRAY,
            subs={0: Var("Number of entries", UNSIGNED8, "ro", 2),
                  1: Var("Force limit N", UNSIGNED16, "rw", 300),
                  2: Var("Torque limit N m", UNSIGNED16, "rw", 30)}),
    ]
    return "SpaceArm six-axis force/torque sensor", objs


def sim_control() -> tuple[str, list[Obj]]:
    """Fault-injection unit of the simulated test rig (not an arm device)."""
    objs = [
        v(od.DEVICE_TYPE, "Device type", UNSIGNED32, "ro", 0),
        v(od.ERROR_REGISTER, "Error register", UNSIGNED8, "ro", 0),
        v(od.DEVICE_NAME, "Manufacturer device name", VISIBLE_STRING, "const", "SpaceArm sim fault injection"),
        Obj(od.IDENTITY, "Identity object", RECORD,
            subs={0: Var("Number of entries", UNSIGNED8, "ro", 4),
                  1: Var("Vendor-ID", UNSIGNED32, "ro", VENDOR_ID),
                  2: Var("Product code", UNSIGNED32, "ro", 0x0F1F_0001),
                  3: Var("Revision number", UNSIGNED32, "ro", 0x0001_0000),
                  4: Var("Serial number", UNSIGNED32, "ro", 0)}),
        v(od.SIM_TARGET_NODE, "Target node ID", UNSIGNED8, "rw", 1, low=1, high=127),
        v(od.SIM_SILENT, "Silent", UNSIGNED8, "rw", 0, high=1),
        v(od.SIM_HEARTBEAT_STOPPED, "Heartbeat stopped", UNSIGNED8, "rw", 0, high=1),
        v(od.SIM_SDO_ABORT, "SDO abort code", UNSIGNED32, "rw", 0),
        v(od.SIM_DROP_TPDOS, "Drop next TPDOs", UNSIGNED16, "rw", 0),
        v(od.SIM_CORRUPT_TPDOS, "Corrupt next TPDOs", UNSIGNED16, "rw", 0),
        v(od.SIM_RAISE_FAULT, "Raise fault (EMCY code)", UNSIGNED16, "rw", 0),
        v(od.SIM_STALL, "Stall joint", UNSIGNED8, "rw", 0, high=1),
        v(od.SIM_TEMPERATURE, "Drive temperature", INTEGER16, "rw", 250),
        v(od.SIM_POWER_CYCLE, "Power cycle", UNSIGNED8, "rw", 0, high=1),
        v(od.SIM_EE_TARGET_PRESENT, "End-effector target present", UNSIGNED8, "rw", 1, high=1),
        Obj(od.SIM_WRENCH, "Wrench at the F/T sensor", ARRAY,
            subs={0: Var("Number of entries", UNSIGNED8, "ro", 6),
                  **{i + 1: Var(f"{n} (mN, mN m)", INTEGER32, "rw", 0)
                     for i, n in enumerate(("Fx", "Fy", "Fz", "Tx", "Ty", "Tz"))}}),
        v(od.SIM_IGNORE_SYNC, "Ignore SYNC", UNSIGNED8, "rw", 0, high=1),
        v(od.SIM_FREEZE, "Freeze process data", UNSIGNED8, "rw", 0, high=1),
    ]
    return "SpaceArm simulation fault-injection unit (test rig only)", objs


BUILDERS = {"joint_drive": joint_drive, "joint_drive_compact": joint_drive_compact, "end_effector": end_effector,
            "ft_sensor": ft_sensor, "sim_control": sim_control}
# CiA 306 [FileInfo] dates of this generation of the files (mm-dd-yyyy, hh:mm AM/PM)
CREATED = ("11-23-2026", "12:00AM")
MODIFIED = ("11-24-2026", "12:00AM")


def _fmt(value) -> str:
    if isinstance(value, int):
        return f"0x{value & 0xFFFFFFFF:X}" if value >= 0 else str(value)
    return str(value)


def _var_lines(section: str, var: Var, obj_type: int = VAR) -> list[str]:
    lines = [f"[{section}]", f"ParameterName={var.name}", f"ObjectType=0x{obj_type:X}",
             f"DataType=0x{var.data_type:04X}", f"AccessType={var.access}"]
    if var.default is not None:
        lines.append(f"DefaultValue={_fmt(var.default)}")
    if var.low is not None:
        lines.append(f"LowLimit={_fmt(var.low)}")
    if var.high is not None:
        lines.append(f"HighLimit={_fmt(var.high)}")
    lines.append(f"PDOMapping={1 if var.pdo else 0}")
    return lines + [""]


def render(device: str) -> str:
    description, objs = BUILDERS[device]()
    objs = sorted(objs, key=lambda o: o.index)
    identity = next(o for o in objs if o.index == od.IDENTITY)
    product = identity.subs[2].default
    mandatory = [o for o in objs if o.index in (od.DEVICE_TYPE, od.ERROR_REGISTER, od.IDENTITY)]
    optional = [o for o in objs if o not in mandatory and o.index < 0x2000 or o.index >= 0x6000]
    manufacturer = [o for o in objs if 0x2000 <= o.index < 0x6000]
    out = [
        "; Generated by firmware_sim/eds_builder.py from base/canopen/od.py. Do not edit by hand.",
        "[FileInfo]", f"FileName={device}.eds", "FileVersion=1", "FileRevision=0", "EDSVersion=4.0",
        f"Description={description}", f"CreationTime={CREATED[1]}", f"CreationDate={CREATED[0]}",
        "CreatedBy=spacearm", f"ModificationTime={MODIFIED[1]}", f"ModificationDate={MODIFIED[0]}",
        "ModifiedBy=spacearm", "",
        "[DeviceInfo]", "VendorName=SpaceArm simulation", f"VendorNumber=0x{VENDOR_ID:X}",
        f"ProductName={description}", f"ProductNumber=0x{product:X}", "RevisionNumber=0x00010000",
        f"OrderCode=SA-{device.upper().replace('_', '-')}",
        "BaudRate_10=0", "BaudRate_20=0", "BaudRate_50=0", "BaudRate_125=0", "BaudRate_250=0",
        "BaudRate_500=0", "BaudRate_800=0", "BaudRate_1000=1",
        "SimpleBootUpMaster=0", "SimpleBootUpSlave=1", "Granularity=8", "DynamicChannelsSupported=0",
        "GroupMessaging=0",
        f"NrOfRXPDO={sum(od.RPDO_COMM <= o.index < od.RPDO_COMM + od.N_PDOS for o in objs)}",
        f"NrOfTXPDO={sum(od.TPDO_COMM <= o.index < od.TPDO_COMM + od.N_PDOS for o in objs)}",
        "LSS_Supported=0", "",
        "[DummyUsage]", *[f"Dummy{i:04d}=0" for i in range(1, 8)], "",
    ]
    for title, group in (("MandatoryObjects", mandatory), ("OptionalObjects", optional),
                         ("ManufacturerObjects", manufacturer)):
        out.append(f"[{title}]")
        out.append(f"SupportedObjects={len(group)}")
        out += [f"{i + 1}=0x{o.index:04X}" for i, o in enumerate(group)]
        out.append("")
    for o in objs:
        if o.kind == VAR:
            out += _var_lines(f"{o.index:04X}", o.var)
        else:
            out += [f"[{o.index:04X}]", f"ParameterName={o.name}", f"ObjectType=0x{o.kind:X}",
                    f"SubNumber={len(o.subs)}", ""]
            for sub, var in sorted(o.subs.items()):
                out += _var_lines(f"{o.index:04X}sub{sub:X}", var)
    return "\n".join(out)


def main() -> None:
    EDS_DIR.mkdir(parents=True, exist_ok=True)
    for device in BUILDERS:
        (EDS_DIR / f"{device}.eds").write_text(render(device))
        print(EDS_DIR / f"{device}.eds")


if __name__ == "__main__":
    main()
