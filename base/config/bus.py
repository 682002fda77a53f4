"""Schema of a bus file (configs/bus/*.toml): which nodes are on the CAN bus and how
the controller configures them at bring-up.

All quantities are SI (s, rad, rad/s, N, N m) except where a key names its unit; a linear
axis' joint drive (feed_constant given) is in m, m/s, m/s^2 and N instead of rad and N m.
Wire scaling of the joint drives uses the CiA 402 objects 608Fh (position encoder
resolution), 6091h (gear ratio) and, on a linear axis, 6092h (feed constant): increments per
joint unit = encoder_increments / motor_revolutions * gear_motor_revolutions /
gear_shaft_revolutions / (2 pi rad, or feed_constant m); see base/canopen/axis_scale.py.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, model_validator

from spacearm.base.canopen.axis_scale import AxisScale, feed_counts
from spacearm.base.config.errors import ConfigError
from spacearm.base.config.loader import StrictModel, load_toml_model
from spacearm.base.config.redundancy import RedundancySettings
from spacearm.base.paths import CONFIGS

EDS_DIR = CONFIGS / "eds"
# generic: any CiA 301 device; the master configures and supervises it and carries its PDOs as
# raw object values, with no device-specific meaning
DeviceType = Literal["joint_drive", "end_effector", "ft_sensor", "generic"]


ObjectRef = Annotated[str, Field(pattern=r"^0x[0-9A-Fa-f]{4}(:(0x)?[0-9A-Fa-f]{1,2})?$",
                                   description="object as 0xINDEX or 0xINDEX:SUB (sub in hex)")]


def parse_object_ref(ref: str) -> tuple[int, int]:
    """'0x6040' -> (0x6040, 0); '0x607D:2' / '0x607D:0x02' -> (0x607D, 2)."""
    index, _, sub = ref.partition(":")
    return int(index, 16), int(sub, 16) if sub else 0


class BusSettings(StrictModel):
    sync_period: float = Field(default=0.02, ge=0.001, le=1.0, description="s, SYNC producer period")
    boot_timeout: float = Field(default=3.0, gt=0.0, le=60.0, description="s to wait for all boot-ups")
    sdo_timeout: float = Field(default=0.5, ge=0.01, le=10.0, description="s per SDO response")
    heartbeat_loss_factor: float = Field(
        default=2.5, ge=1.2, le=3.0,
        description="a node is lost when silent for this many of its heartbeat periods (<= 3)")
    lockstep_timeout: float = Field(default=0.5, gt=0.0, le=10.0,
                                    description="s to wait for all TPDOs of one SYNC in lockstep mode")
    master_node_id: int = Field(default=127, ge=1, le=127,
                                description="node ID of the controller's own heartbeat (0x700 + id)")
    master_heartbeat_period: float = Field(default=0.1, ge=0.0, le=65.0,
                                           description="s; controller heartbeat producer, 0 = off")
    master_heartbeat_timeout: float = Field(
        default=0.3, ge=0.0, le=65.0,
        description="s; every node consumes the controller heartbeat (1016h) and faults/stops "
                    "when it is silent this long; 0 = off")
    tpdo_loss_cycles: int = Field(default=5, ge=2, le=1000,
                                  description="a mapped TPDO missing for this many SYNCs in a row is a "
                                              "fault (tpdo_missing), like a lost heartbeat")
    redundancy: RedundancySettings = Field(default_factory=RedundancySettings,
                                           description="bus redundancy on a redundant pair of lines (A+B)")


class JointSettings(StrictModel):
    encoder_increments: int = Field(default=1 << 20, ge=1, le=2**31, description="608Fh.1 per motor_revolutions")
    motor_revolutions: int = Field(default=1, ge=1, le=2**16, description="608Fh.2")
    gear_motor_revolutions: int = Field(default=100, ge=1, le=2**20, description="6091h.1")
    gear_shaft_revolutions: int = Field(default=1, ge=1, le=2**20, description="6091h.2")
    feed_constant: float | None = Field(
        default=None, ge=1.0e-6, le=1.0,
        description="m of travel per shaft revolution (6092h; a screw's lead): the joint is a linear axis and "
                    "every position, speed, limit and window of this drive is in m, its torque a force in N; "
                    "none: a rotary joint, 2 pi rad per shaft revolution")
    rated_torque: float = Field(default=1.5, gt=0.0, le=1000.0, description="N m, motor side (6076h)")
    max_torque: float = Field(default=1.0, gt=0.0, le=3.0, description="fraction of rated torque (6072h)")
    following_error_window: float = Field(default=0.01, gt=0.0, le=1.0, description="rad or m (6065h)")
    following_error_timeout: float = Field(default=0.1, ge=0.0, le=65.0, description="s (6066h)")
    lower: float = Field(default=-2 * math.pi, ge=-6 * math.pi, le=6 * math.pi, description="rad or m (607Dh.1)")
    upper: float = Field(default=2 * math.pi, ge=-6 * math.pi, le=6 * math.pi, description="rad or m (607Dh.2)")
    max_velocity: float = Field(default=1.0, gt=0.0, le=10.0, description="rad/s or m/s (607Fh)")
    profile_velocity: float = Field(default=0.1, gt=0.0, le=10.0, description="rad/s or m/s (6081h)")
    profile_acceleration: float = Field(default=0.2, gt=0.0, le=100.0, description="rad/s^2 or m/s^2 (6083h/6084h)")
    quick_stop_deceleration: float = Field(default=1.0, gt=0.0, le=100.0, description="rad/s^2 or m/s^2 (6085h)")
    quick_stop_option: int = Field(default=2, ge=0, le=8, description="605Ah: 2 stop then disable, 6 stay in quick stop")
    # Manufacturer objects mean what this drive's maker says: named here per node, never assumed
    temperature_object: ObjectRef | None = Field(
        default=None, description="object holding the drive temperature (INTEGER16, 0.1 degC); none: not reported")
    brake_object: ObjectRef | None = Field(
        default=None, description="object that is 1 while the holding brake is engaged; none: not reported")

    @model_validator(mode="after")
    def _ordered(self) -> "JointSettings":
        if not self.lower < self.upper:
            raise ValueError(f"lower ({self.lower}) must be less than upper ({self.upper})")
        if not self.profile_velocity <= self.max_velocity:
            raise ValueError("profile_velocity must not exceed max_velocity")
        if self.feed_constant is not None and abs(feed_counts(self.feed_constant) * 1e-6 - self.feed_constant) > 1e-12:
            raise ValueError(f"feed_constant {self.feed_constant} m is not a whole number of micrometres "
                             f"(6092h carries um per shaft revolution)")
        return self

    @property
    def scale(self) -> AxisScale:
        """The configured wire scaling (the drive's own reported values replace it at bring-up)."""
        return AxisScale(self.encoder_increments, self.motor_revolutions, self.gear_motor_revolutions,
                         self.gear_shaft_revolutions, self.rated_torque,
                         None if self.feed_constant is None else feed_counts(self.feed_constant))

    @property
    def linear(self) -> bool:
        return self.feed_constant is not None

    @property
    def increments_per_rad(self) -> float:
        """Increments per joint unit: per rad, or per m on a linear axis."""
        return self.scale.per_unit

    @property
    def gear_ratio(self) -> float:
        return self.gear_motor_revolutions / self.gear_shaft_revolutions

    @property
    def rated_joint_torque(self) -> float:
        """N m at the joint output for 1000 per mille (motor rated torque times gear ratio);
        N along a linear axis (through the screw)."""
        return self.scale.rated_joint


class EndEffectorSettings(StrictModel):
    lock_torque: float = Field(default=8.0, ge=0.1, le=30.0, description="N m screw torque that means locked (2110h)")
    lock_turns: float = Field(default=6.0, ge=0.1, le=100.0, description="screw turns to full lock (2111h)")


class FtSettings(StrictModel):
    force_counts_per_n: int = Field(default=100, ge=1, le=10000, description="2201h")
    torque_counts_per_nm: int = Field(default=1000, ge=1, le=100000, description="2202h")
    force_limit: int = Field(default=300, ge=1, le=65535, description="N, overload (2205h.1)")
    torque_limit: int = Field(default=30, ge=1, le=65535, description="N m, overload (2205h.2)")


class PdoEntry(StrictModel):
    """One PDO given as a table: which PDO of the device (any number its EDS offers), on which
    COB-ID (default: the pre-defined connection set, PDO1..4 only), mapping which objects."""
    number: int = Field(ge=1, le=512, description="PDO number, 1-based (RPDO1 = 1, as CiA 301 counts)")
    cob_id: int | None = Field(default=None, ge=1, le=0x7FF, description=(
        "11-bit COB-ID; required beyond PDO4, which have no pre-defined one"))
    objects: list[ObjectRef] = Field(min_length=1, max_length=8)


class PdoLayout(StrictModel):
    """The PDOs a node is configured with, per direction. Each item is either a list of mapped
    objects (the item's position gives its number: the first is PDO1; an empty list leaves
    that PDO disabled) or a table {number, cob_id, objects} for any PDO the EDS offers and an
    explicit COB-ID. Every PDO of the device not named here is disabled at bring-up. Object
    sizes come from the node's EDS, which must allow the mapping (checked at load)."""
    rpdo: list[list[ObjectRef] | PdoEntry] = Field(default_factory=list, max_length=512)
    tpdo: list[list[ObjectRef] | PdoEntry] = Field(default_factory=list, max_length=512)

    @model_validator(mode="after")
    def _numbers_unique(self) -> "PdoLayout":
        for kind in ("rpdo", "tpdo"):
            seen: set[int] = set()
            for number, _, _ in self.entries(kind):
                if number in seen:
                    raise ValueError(f"{kind.upper()}{number} given twice")
                seen.add(number)
        return self

    def entries(self, kind: str) -> list[tuple[int, int | None, list[str]]]:
        """(number 1-based, COB-ID or None, object refs) of each configured (non-empty) PDO."""
        out = []
        for position, item in enumerate(getattr(self, kind), start=1):
            if isinstance(item, PdoEntry):
                out.append((item.number, item.cob_id, list(item.objects)))
            elif item:
                out.append((position, None, list(item)))
        return out


class NodeConfig(StrictModel):
    name: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z_][A-Za-z0-9_]*$")
    node_id: int = Field(ge=1, le=127)
    device: DeviceType
    heartbeat_period: float = Field(default=0.1, ge=0.01, le=65.0, description="s (1017h)")
    joint: JointSettings | None = None
    end_effector: EndEffectorSettings | None = None
    ft: FtSettings | None = None
    eds: str | None = Field(default=None, min_length=1, description=(
        "the node's EDS/DCF (relative to configs/eds/ or absolute); default configs/eds/<device>.eds"))
    pdo: PdoLayout | None = Field(default=None, description="PDO mapping; default: the layout the "
                                  "node's EDS gives by default")
    sdo: dict[ObjectRef, int] = Field(default_factory=dict, description=(
        "extra SDO writes at bring-up, object -> raw value, in file order (as ros2_canopen's sdo: "
        "list); each object must exist and be writable in the EDS"))
    strict: bool = Field(default=False, description=(
        "every object the device refuses at bring-up stops the boot; default: a refused optional "
        "object (CiA 301/402) is listed in the bring-up report and its fallback used"))

    @model_validator(mode="after")
    def _settings_match_device(self) -> "NodeConfig":
        for key, device in (("joint", "joint_drive"), ("end_effector", "end_effector"), ("ft", "ft_sensor")):
            if getattr(self, key) is not None and self.device != device:
                raise ValueError(f"[{key}] settings given for a {self.device} node")
        # fill in defaults so users of the config never see None for their own device
        if self.device == "joint_drive" and self.joint is None:
            object.__setattr__(self, "joint", JointSettings())
        if self.device == "end_effector" and self.end_effector is None:
            object.__setattr__(self, "end_effector", EndEffectorSettings())
        if self.device == "ft_sensor" and self.ft is None:
            object.__setattr__(self, "ft", FtSettings())
        return self

    @property
    def eds_path(self) -> Path:
        if self.eds is None:
            return EDS_DIR / f"{self.device}.eds"
        path = Path(self.eds)
        return path if path.is_absolute() else EDS_DIR / path

    @property
    def label(self) -> str:
        return f"node {self.node_id} '{self.name}' ({self.device})"


class BusConfig(StrictModel):
    bus: BusSettings = BusSettings()
    nodes: list[NodeConfig] = Field(min_length=1, max_length=127)

    @model_validator(mode="after")
    def _unique(self) -> "BusConfig":
        seen_ids: dict[int, str] = {}
        seen_names: set[str] = set()
        for node in self.nodes:
            if node.node_id == self.bus.master_node_id:
                raise ValueError(f"node '{node.name}' uses node_id {node.node_id}, the controller's "
                                 f"bus.master_node_id")
            if node.node_id in seen_ids:
                raise ValueError(f"node_id {node.node_id} used by both '{seen_ids[node.node_id]}' and '{node.name}'")
            if node.name in seen_names:
                raise ValueError(f"node name '{node.name}' used twice")
            seen_ids[node.node_id] = node.name
            seen_names.add(node.name)
        return self

    def of_device(self, device: str) -> list[NodeConfig]:
        return [n for n in self.nodes if n.device == device]

    @property
    def joints(self) -> list[NodeConfig]:
        return self.of_device("joint_drive")

    def node(self, name_or_id: str | int) -> NodeConfig:
        for n in self.nodes:
            if n.name == name_or_id or n.node_id == name_or_id:
                return n
        raise KeyError(f"no node {name_or_id!r} in bus config")

    def without(self, *names: str) -> "BusConfig":
        """A copy with the named nodes removed (tests: a bus with a node missing)."""
        return BusConfig(bus=self.bus, nodes=[n for n in self.nodes if n.name not in names])


DEFAULT_BUS_CONFIG = CONFIGS / "bus" / "arm.toml"


def check_axis_kinds(bus: BusConfig, kinds: list[str], arm_source: str) -> None:
    """Refuse (one line) a joint drive whose kind of axis disagrees with its joint's (the arm
    file's for the master, the plant's for the simulator): a prismatic joint needs its drive's
    feed constant (without it the drive would be scaled in rad), a revolute joint must not
    have one."""
    for i, (node, kind) in enumerate(zip(bus.joints, kinds)):
        if kind == "prismatic" and not node.joint.linear:
            raise ConfigError(f"joint {i + 1} is prismatic in {arm_source} but its drive {node.label} has no "
                              f"[nodes.joint] feed_constant (m per shaft revolution, 6092h)")
        if kind != "prismatic" and node.joint.linear:
            raise ConfigError(f"joint {i + 1} is {kind} in {arm_source} but its drive {node.label} has a "
                              f"feed_constant ({node.joint.feed_constant} m): only a linear axis has one")


def load_bus_config(path: str | Path = DEFAULT_BUS_CONFIG) -> BusConfig:
    return load_toml_model(path, BusConfig)


def dump_toml(config: BusConfig) -> str:
    """TOML text of a bus config (e.g. a test's variant written for a `spacearm sim` process)."""
    def value(v) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)          # a JSON string is a valid TOML basic string
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, dict):           # an inline table ([nodes.pdo] entries)
            return "{" + ", ".join(f"{k} = {value(x)}" for k, x in v.items() if x is not None) + "}"
        return repr(v)

    lines = ["[bus]"] + [f"{k} = {value(v)}" for k, v in config.bus.model_dump().items()]
    for node in config.nodes:
        lines += ["", "[[nodes]]"]
        data = node.model_dump()
        tables = {k: data.pop(k) for k in ("joint", "end_effector", "ft", "pdo", "sdo")}
        if data.get("eds") is None:
            data.pop("eds", None)
        lines += [f"{k} = {value(v)}" for k, v in data.items()]
        for key, table in tables.items():
            if table:
                lines.append(f"[nodes.{key}]")
                lines += [f"{json.dumps(k) if ':' in k else k} = {value(v)}" for k, v in table.items()
                          if v is not None]          # TOML has no null: an absent key is the default
    return "\n".join(lines) + "\n"
