"""Per-device drivers: configuration by SDO, TPDO decoding and RPDO encoding in SI units.

Nothing outside drivers/ sees a COB-ID or an index: these classes turn PDO bytes into the
dataclasses below and commands in SI units back into PDO bytes.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from operator import itemgetter

import canopen

from spacearm.base.canopen import od
from spacearm.base.canopen.od import EeCommand, EeState  # noqa: F401  (re-exported for callers)
from spacearm.base.config.bus import BusSettings, NodeConfig, parse_object_ref
from spacearm.drivers.cia402 import Cia402Axis
from spacearm.drivers.joint_rpdos import compile_rpdo_packer
from spacearm.base.canopen.cia402_defs import (CW_CHANGE_IMMEDIATELY, CW_HALT, CW_NEW_SETPOINT, SW_INTERNAL_LIMIT, SW_OP_MODE_12,
                                 SW_TARGET_REACHED, State,
                                 decode_statusword)
from spacearm.drivers.pdo_config import PdoSpec, resolve_layout
from spacearm.drivers.reported_values import ReportedValues


def compile_pdo(spec: PdoSpec) -> tuple[struct.Struct, tuple[tuple[int, int], ...]] | None:
    """One struct for the whole PDO (built once per mapping) when every entry is a number whose
    struct size is its mapped size; None otherwise (24/40/48/56-bit types, strings), and the
    caller codes entry by entry as the library does."""
    codes = []
    for e in spec.entries:
        packer = e.var.STRUCT_TYPES.get(e.var.data_type)
        if packer is None or packer.size != e.size:
            return None
        codes.append(packer.format.lstrip("<"))
    return struct.Struct("<" + "".join(codes)), tuple((e.index, e.sub) for e in spec.entries)


@dataclass
class JointState:
    name: str
    node_id: int
    state: State = State.NOT_READY_TO_SWITCH_ON
    statusword: int = 0
    position: float = 0.0          # rad (m on a linear axis)
    velocity: float = 0.0          # rad/s (m/s)
    torque: float = 0.0            # N m at the joint (motor torque x gear ratio); N along a linear axis
    following_error: float = 0.0   # rad (m)
    temperature: float = float("nan")  # degC (nan: the drive's configuration names no such object)
    brake_engaged: bool | None = True  # None: not reported
    error_code: int = 0
    mode: int = 0

    @property
    def enabled(self) -> bool:
        return self.state == State.OPERATION_ENABLED

    @property
    def fault(self) -> bool:
        return self.state in (State.FAULT, State.FAULT_REACTION_ACTIVE)

    @property
    def limit_active(self) -> bool:
        """Statusword bit 11: the drive clamped the target (position or velocity limit)."""
        return bool(self.statusword & SW_INTERNAL_LIMIT)

    @property
    def target_reached(self) -> bool:
        """Statusword bit 10 (profile position: the last set-point is reached)."""
        return bool(self.statusword & SW_TARGET_REACHED)


@dataclass
class EndEffectorState:
    name: str
    node_id: int
    state: EeState = EeState.UNKNOWN
    grip: float = 0.0              # 0 open .. 1 closed
    screw_torque: float = 0.0      # N m
    screw_turns: float = 0.0       # turns
    fault_code: int = 0


@dataclass
class FtState:
    name: str
    node_id: int
    force: tuple[float, float, float] = (0.0, 0.0, 0.0)    # N
    torque: tuple[float, float, float] = (0.0, 0.0, 0.0)   # N m
    overload: bool = False
    tared: bool = False


class DeviceDriver(ReportedValues):
    device = ""

    def __init__(self, cfg: NodeConfig, bus: BusSettings, object_dictionary: canopen.ObjectDictionary):
        self.cfg = cfg
        self.bus = bus
        self.od = object_dictionary
        self.name, self.node_id, self.label = cfg.name, cfg.node_id, cfg.label
        self._values: dict[tuple[int, int], int] = {}     # `values` (drivers/reported_values.py)
        self.latest = None
        self.rpdo_values: dict[tuple[int, int], int] = {}
        # the configured layout, checked against the EDS (MappingError names node, PDO, object)
        self.set_layout(*resolve_layout(cfg, object_dictionary))

    def set_layout(self, rpdos, tpdos) -> None:
        """The PDO layout, and its codecs compiled once from it: a frame then costs one
        unpack/pack and no lookup by object or by spec. The layout is replaced whole (tuples),
        so the codecs cannot silently describe another mapping than the one in use."""
        self._use_tpdo_keys(tpdos)
        self._rpdos, self._tpdos = tuple(rpdos), tuple(tpdos)
        self.tpdo_codecs = {spec.cob_id: PdoCodec(spec) for spec in self._tpdos}
        self._rpdo_codecs = tuple(PdoCodec(spec) for spec in self._rpdos)
        # what CyclicIO.write packs each cycle without a call per driver: (COB-ID, pack, keys,
        # zeros) per RPDO; None where one codes entry by entry (rpdo_frames then)
        packs = tuple((c.cob_id, c.struct.pack, c.keys, c.zeros) for c in self._rpdo_codecs if c.struct is not None)
        self.rpdo_packs = packs if len(packs) == len(self._rpdo_codecs) else None

    @property
    def rpdos(self) -> tuple[PdoSpec, ...]:
        return self._rpdos

    @property
    def tpdos(self) -> tuple[PdoSpec, ...]:
        return self._tpdos

    # bring-up -------------------------------------------------------------------
    def config_writes(self) -> list[tuple[int, int, int]]:
        """(index, sub, value) written by SDO before PDO mapping; device specific."""
        return []

    def hardware_objects(self) -> list[tuple[int, int, int]]:
        """(index, sub, configured value) of fixed hardware data (scaling). Bring-up writes
        them where the EDS says writable, else reads them and calls use_hardware()."""
        return []

    def use_hardware(self, values: dict[tuple[int, int], int]) -> None:
        """Scaling from the hardware data the device reported (read-only objects)."""

    # cycle ------------------------------------------------------------------------
    def decode(self, spec: PdoSpec, data: bytes) -> None:
        codec = self.tpdo_codecs.get(spec.cob_id)
        if codec is None or codec.spec is not spec:
            codec = PdoCodec(spec)       # a spec outside the layout (tests): coded, not kept
        codec.decode_into(self.values, data)

    def value(self, index: int, sub: int = 0, default=0):
        return self.values.get((index, sub), default)

    def step(self) -> None:
        """Once per cycle after this SYNC's TPDOs: advance internal state machines."""

    def rpdo_frames(self) -> list[tuple[int, bytes]]:
        values, frames = self.rpdo_values, []
        for codec in self._rpdo_codecs:
            if codec.struct is not None:    # PdoCodec.encode's common case, without its call
                frames.append((codec.cob_id, codec.struct.pack(*map(values.get, codec.keys, codec.zeros))))
            else:
                frames.append((codec.cob_id, codec.encode(values)))
        return frames


class PdoCodec:
    """One PDO's coding, compiled from its mapping: one struct for the whole frame where every
    entry is a number of its mapped size (compile_pdo), else entry by entry as the library
    codes them (24/40/48/56-bit types, strings). Objects missing from the values encode as 0."""

    __slots__ = ("spec", "cob_id", "length", "keys", "struct", "zeros")

    def __init__(self, spec: PdoSpec):
        self.spec, self.cob_id, self.length = spec, spec.cob_id, spec.length
        self.keys = tuple((e.index, e.sub) for e in spec.entries)
        compiled = compile_pdo(spec)
        self.struct = compiled[0] if compiled is not None else None
        self.zeros = (0,) * len(self.keys)     # the default of each object not in the values

    def decode_into(self, values: dict, data) -> None:
        if self.struct is not None:
            values.update(zip(self.keys, self.struct.unpack_from(data)))
            return
        offset = 0
        for e in self.spec.entries:
            values[(e.index, e.sub)] = e.var.decode_raw(bytes(data[offset:offset + e.size]))
            offset += e.size

    def encode(self, values: dict) -> bytes:
        if self.struct is not None:
            return self.struct.pack(*map(values.get, self.keys, self.zeros))
        return b"".join(e.var.encode_raw(values.get(key, 0)) for e, key in zip(self.spec.entries, self.keys))


# 605Eh: a drive that faults while moving stops on its quick-stop ramp (6085h) before the brake
FAULT_REACTION_QUICK_STOP_RAMP = 2


class JointDriver(DeviceDriver):
    device = "joint_drive"

    def __init__(self, cfg, bus, object_dictionary):
        super().__init__(cfg, bus, object_dictionary)
        self.settings = cfg.joint
        self.scale = self.settings.scale                  # the wire's factor group (axis_scale.py)
        self.k = self.scale.per_unit                      # increments per joint rad (m on a linear axis)
        self.rated_joint_torque = self.scale.rated_joint  # N m (N if linear) at the joint per 1000 per mille
        self.axis = Cia402Axis(cfg.label)
        self.target: float | None = None        # rad, CSP target requested by the caller
        self.velocity_ff = 0.0                   # rad/s
        self.torque_ff = 0.0                     # N m at the joint
        self.halt = False                        # controlword bit 8: the drive stops on 605Dh's ramp, stays enabled
        self._hold: float | None = None
        self.mode = od.MODE_CSP
        self._pp_pending = False                 # profile position: set-point sent, not yet acknowledged
        self._pp_sent: float | None = None
        self.rpdo_values[(od.MODES_OF_OPERATION, 0)] = od.MODE_CSP
        # reported only where this node's configuration names the object and a TPDO carries it
        mapped = {(e.index, e.sub) for spec in self.tpdos for e in spec.entries}
        s = self.settings
        self._temperature = _mapped_ref(s.temperature_object, mapped)
        self._brake = _mapped_ref(s.brake_object, mapped)
        # state()'s objects read in one call once the drive reported them all (a lookup per
        # object and joint was ~60 dict.get a cycle, issue 35), the optional ones last; None
        # where the layout leaves one out (state() would fail over to the lookups every cycle)
        self._state_keys = (*_STATE_KEYS, *(key for key in (self._temperature, self._brake) if key))
        self._reported = itemgetter(*self._state_keys) if mapped.issuperset(_STATE_KEYS) else None
        self._compile_readers()

    def _compile_readers(self) -> None:
        # the same objects read by position from a burst's tuple (drivers/reported_values.py)
        self._state_at = self.tuple_reader(self._state_keys) if self._reported is not None else None
        self._step_at = self.tuple_reader((_STATUSWORD, _POSITION_ACTUAL))
        self._reading_at = self.tuple_reader(_STATE_KEYS[:4]) if self._state_at is not None else None

    def set_mode(self, mode: int) -> None:
        """od.MODE_CSP (cyclic synchronous position) or od.MODE_PROFILE_POSITION."""
        if mode not in (od.MODE_CSP, od.MODE_PROFILE_POSITION):
            raise ValueError(f"{self.label}: unsupported mode {mode}")
        self.mode = mode
        self.target = None
        self._hold = None                        # hold where the joint is now
        self._pp_pending, self._pp_sent = False, None
        self.rpdo_values[(od.MODES_OF_OPERATION, 0)] = mode

    def hardware_objects(self):
        return self.scale.wire_objects()

    def use_hardware(self, values):
        """Scaling from the drive's own 608Fh/6091h/6092h/6076h where it reported them."""
        self.scale = self.settings.scale.with_reported(values)
        self.k = self.scale.per_unit
        self.rated_joint_torque = self.scale.rated_joint

    def config_writes(self):
        s, k = self.settings, self.k
        return [
            (od.MAX_TORQUE, 0, round(s.max_torque * 1000)),
            (od.FOLLOWING_ERROR_WINDOW, 0, round(s.following_error_window * k)),
            (od.FOLLOWING_ERROR_TIMEOUT, 0, round(s.following_error_timeout * 1000)),
            (od.SOFTWARE_POSITION_LIMIT, 1, _clamp32(round(s.lower * k))),
            (od.SOFTWARE_POSITION_LIMIT, 2, _clamp32(round(s.upper * k))),
            (od.MAX_PROFILE_VELOCITY, 0, round(s.max_velocity * k)),
            (od.PROFILE_VELOCITY, 0, round(s.profile_velocity * k)),
            (od.PROFILE_ACCELERATION, 0, round(s.profile_acceleration * k)),
            (od.PROFILE_DECELERATION, 0, round(s.profile_acceleration * k)),
            (od.QUICK_STOP_DECELERATION, 0, round(s.quick_stop_deceleration * k)),
            (od.QUICK_STOP_OPTION, 0, s.quick_stop_option),
            (od.FAULT_REACTION_OPTION, 0, FAULT_REACTION_QUICK_STOP_RAMP),
            (od.INTERPOLATION_TIME_PERIOD, 1, round(self.bus.sync_period * 1000)),
            (od.INTERPOLATION_TIME_PERIOD, 2, -3),
            (od.MODES_OF_OPERATION, 0, od.MODE_CSP),
        ]

    @property
    def position(self) -> float:
        # from a burst's tuple, not merged into the dict for this (the master's following-error
        # check reads it every cycle on a drive without 6065h)
        latest = self.latest
        if latest is not None and self._step_at is not None:
            return self._step_at(latest)[1] / self.k
        return self.values.get(_POSITION_ACTUAL, 0) / self.k

    def set_layout(self, rpdos, tpdos) -> None:
        super().set_layout(rpdos, tpdos)
        self._pack_rpdos = compile_rpdo_packer(self._rpdo_codecs)    # step_frames' packing
        if hasattr(self, "_state_keys"):      # a new layout after __init__
            self._compile_readers()

    def step(self) -> None:
        self.step_frames()

    def step_frames(self) -> list[tuple[int, bytes]]:
        """step(), and the RPDO frames of what it computed, packed from its values (the frames
        rpdo_frames() would give after it; drivers/joint_rpdos.py)."""
        latest = self.latest
        if latest is not None and self._step_at is not None:
            statusword, actual = self._step_at(latest)
        else:
            get = self.values.get
            statusword, actual = get(_STATUSWORD, 0), get(_POSITION_ACTUAL, 0)
        axis = self.axis
        cw = axis.step(statusword)
        if axis.state != _OPERATION_ENABLED:
            # not enabled: command the actual position so enabling never jumps
            self._hold = actual / self.k
            self.target = None
            target = self._hold
        else:
            if self._hold is None:
                self._hold = actual / self.k
            target = self.target if self.target is not None else self._hold
        if self.mode == od.MODE_PROFILE_POSITION:
            # set-point handshake: bit 4 high until the drive acknowledges (statusword bit 12)
            if self._pp_pending and statusword & SW_OP_MODE_12:
                self._pp_pending = False
            elif (not self._pp_pending and axis.state == State.OPERATION_ENABLED and self.target is not None
                  and self.target != self._pp_sent and not statusword & SW_OP_MODE_12):
                self._pp_pending, self._pp_sent = True, self.target
            if self._pp_pending:
                cw |= CW_NEW_SETPOINT | CW_CHANGE_IMMEDIATELY
                target = self._pp_sent
            elif self._pp_sent is not None:
                target = self._pp_sent
        if self.halt:
            cw |= CW_HALT
        k = self.k
        # clamped to the objects' ranges by comparisons, not min/max calls (issue 35: 12 of
        # the cycle's built-in calls per joint); the same ints either way. A zero feed-forward
        # (the daemon never sends a torque) is 0 without round(): round(+-0.0) is 0.
        position = round(target * k)
        velocity = round(self.velocity_ff * k) if self.velocity_ff else 0
        torque = round(self.torque_ff / self.rated_joint_torque * 1000) if self.torque_ff else 0
        if not _I32_MIN <= position <= _I32_MAX:
            position = _I32_MIN if position < 0 else _I32_MAX
        if not _I32_MIN <= velocity <= _I32_MAX:
            velocity = _I32_MIN if velocity < 0 else _I32_MAX
        if not -32768 <= torque <= 32767:
            torque = -32768 if torque < 0 else 32767
        rpdo = self.rpdo_values
        rpdo[_CONTROLWORD] = cw
        rpdo[_TARGET_POSITION] = position
        rpdo[_VELOCITY_OFFSET] = velocity
        rpdo[_TORQUE_OFFSET] = torque
        pack = self._pack_rpdos
        if pack is None:
            return self.rpdo_frames()
        return pack(cw, position, velocity, torque, rpdo.get)

    def state(self) -> JointState:
        latest = self.latest
        if latest is not None and self._state_at is not None:
            reported = self._state_at(latest)      # a burst's tuple by position
        elif self._reported is None:
            return self._state_of_defaults()
        else:
            try:
                reported = self._reported(self.values)
            except KeyError:        # before the first TPDOs: one by one, at their defaults
                return self._state_of_defaults()
        statusword = reported[0]
        state = _STATES.get(statusword)
        if state is None:
            state = _STATES[statusword] = decode_statusword(statusword)
        k = self.k
        # every joint every cycle: the fields in JointState's order, without its __init__'s
        # keyword handling (issue 35: half the cost of a state); _STATE_KEYS' order, then the
        # optional objects: the temperature, the brake
        joint = _new(JointState)
        joint.__dict__ = {
            "name": self.name, "node_id": self.node_id,
            "state": state, "statusword": statusword,
            "position": reported[1] / k,
            "velocity": reported[2] / k,
            "torque": reported[3] / 1000.0 * self.rated_joint_torque,
            "following_error": reported[4] / k,
            "temperature": reported[7] / 10.0 if self._temperature else float("nan"),
            "brake_engaged": bool(reported[-1]) if self._brake else None,
            "error_code": reported[5],
            "mode": reported[6],
        }
        return joint

    def reading(self) -> tuple[float, float, float, State]:
        """(position, velocity, torque, state) as state() gives them, without the JointState
        around them (the daemon's Measurement takes these four; issue 35)."""
        latest = self.latest
        if latest is None or self._reading_at is None:
            joint = self.state()
            return joint.position, joint.velocity, joint.torque, joint.state
        statusword, position, velocity, torque = self._reading_at(latest)
        state = _STATES.get(statusword)
        if state is None:
            state = _STATES[statusword] = decode_statusword(statusword)
        k = self.k
        return position / k, velocity / k, torque / 1000.0 * self.rated_joint_torque, state

    def _state_of_defaults(self) -> JointState:
        """state() with every object the drive has not reported yet at its default."""
        get, k = self.values.get, self.k
        statusword = get(_STATUSWORD, 0)
        state = _STATES.get(statusword)
        if state is None:
            state = _STATES[statusword] = decode_statusword(statusword)
        temperature, brake = self._temperature, self._brake
        joint = _new(JointState)
        joint.__dict__ = {
            "name": self.name, "node_id": self.node_id,
            "state": state, "statusword": statusword,
            "position": get(_POSITION_ACTUAL, 0) / k,
            "velocity": get(_VELOCITY_ACTUAL, 0) / k,
            "torque": get(_TORQUE_ACTUAL, 0) / 1000.0 * self.rated_joint_torque,
            "following_error": get(_FOLLOWING_ERROR_ACTUAL, 0) / k,
            "temperature": get(temperature, 0) / 10.0 if temperature else float("nan"),
            "brake_engaged": bool(get(brake, 1)) if brake else None,
            "error_code": get(_ERROR_CODE, 0),
            "mode": get(_MODE_DISPLAY, 0),
        }
        return joint


# the cycle's objects as value keys, built once (the drivers read and write them every cycle)
_STATUSWORD, _POSITION_ACTUAL = (od.STATUSWORD, 0), (od.POSITION_ACTUAL, 0)
_VELOCITY_ACTUAL, _TORQUE_ACTUAL = (od.VELOCITY_ACTUAL, 0), (od.TORQUE_ACTUAL, 0)
_FOLLOWING_ERROR_ACTUAL, _ERROR_CODE = (od.FOLLOWING_ERROR_ACTUAL, 0), (od.ERROR_CODE, 0)
_MODE_DISPLAY = (od.MODES_OF_OPERATION_DISPLAY, 0)
# what JointDriver.state() reads every cycle, in its unpacking's order
_STATE_KEYS = (_STATUSWORD, _POSITION_ACTUAL, _VELOCITY_ACTUAL, _TORQUE_ACTUAL, _FOLLOWING_ERROR_ACTUAL,
               _ERROR_CODE, _MODE_DISPLAY)
_CONTROLWORD, _TARGET_POSITION = (od.CONTROLWORD, 0), (od.TARGET_POSITION, 0)
_VELOCITY_OFFSET, _TORQUE_OFFSET = (od.VELOCITY_OFFSET, 0), (od.TORQUE_OFFSET, 0)
_I32_MIN, _I32_MAX = -2**31, 2**31 - 1
_FT_VALUES, _FT_STATUS = tuple((od.FT_VALUES, i) for i in range(1, 7)), (od.FT_STATUS, 0)
_EE_STATE, _EE_GRIP, _EE_FAULT_CODE = (od.EE_STATE, 0), (od.EE_GRIP_POSITION, 0), (od.EE_FAULT_CODE, 0)
_EE_SCREW_TORQUE, _EE_SCREW_TURNS = (od.EE_SCREW_TORQUE, 0), (od.EE_SCREW_TURNS, 0)
_EE_KEYS = (_EE_STATE, _EE_GRIP, _EE_SCREW_TORQUE, _EE_SCREW_TURNS, _EE_FAULT_CODE)     # state()'s order
_EE_STATES = dict(EeState._value2member_map_)   # raw value -> member, as EeState(raw)
_EE_UNKNOWN = EeState.UNKNOWN
_STATES: dict[int, State] = {}     # statusword -> its CiA 402 state: a handful of words ever seen
# read by every joint's step: a module name costs a fraction of the enum class's member lookup
_OPERATION_ENABLED = State.OPERATION_ENABLED
_new = object.__new__


class EndEffectorDriver(DeviceDriver):
    device = "end_effector"

    def config_writes(self):
        s = self.cfg.end_effector
        return [(od.EE_SCREW_TORQUE_LIMIT, 0, round(s.lock_torque * 1000)),
                (od.EE_LOCK_TURNS, 0, round(s.lock_turns * 1000))]

    def command(self, command: EeCommand) -> None:
        """Held in the cyclic RPDO; the device acts when the value changes."""
        self.rpdo_values[(od.EE_COMMAND, 0)] = int(command)

    def set_layout(self, rpdos, tpdos) -> None:
        super().set_layout(rpdos, tpdos)
        self._state_at = self.tuple_reader(_EE_KEYS)      # state() from a burst's tuple

    def state(self) -> EndEffectorState:
        latest = self.latest
        if latest is not None and self._state_at is not None:
            raw, grip, torque, turns, fault = self._state_at(latest)
        else:
            get = self.values.get   # every cycle: the dict's get, not value()'s call per object
            raw, grip, torque, turns, fault = [get(key, 0) for key in _EE_KEYS]
        # the fields in EndEffectorState's order, without its __init__'s keyword handling
        state = _new(EndEffectorState)
        state.__dict__ = {
            "name": self.name, "node_id": self.node_id,
            # the member EeState(raw) returns, looked up without the enum's call
            "state": _EE_STATES.get(raw, _EE_UNKNOWN),
            "grip": grip / 1000.0,
            "screw_torque": torque / 1000.0,
            "screw_turns": turns / 1000.0,
            "fault_code": fault}
        return state


class FtDriver(DeviceDriver):
    device = "ft_sensor"

    def config_writes(self):
        s = self.cfg.ft
        return [(od.FT_FORCE_COUNTS_PER_N, 0, s.force_counts_per_n),
                (od.FT_TORQUE_COUNTS_PER_NM, 0, s.torque_counts_per_nm),
                (od.FT_OVERLOAD_LIMIT, 1, s.force_limit),
                (od.FT_OVERLOAD_LIMIT, 2, s.torque_limit)]

    def set_layout(self, rpdos, tpdos) -> None:
        super().set_layout(rpdos, tpdos)
        self._state_at = self.tuple_reader((*_FT_VALUES, _FT_STATUS))      # state() from a burst's tuple

    def state(self) -> FtState:
        s, latest = self.cfg.ft, self.latest
        if latest is not None and self._state_at is not None:
            fx, fy, fz, tx, ty, tz, status = self._state_at(latest)
        else:
            get = self.values.get
            fx, fy, fz, tx, ty, tz = [get(key, 0) for key in _FT_VALUES]
            status = get(_FT_STATUS, 0)
        per_n, per_nm = s.force_counts_per_n, s.torque_counts_per_nm
        # the tuples written out (two generators a cycle cost more than the divisions), the
        # fields in FtState's order without its __init__'s keyword handling
        state = _new(FtState)
        state.__dict__ = {
            "name": self.name, "node_id": self.node_id,
            "force": (fx / per_n, fy / per_n, fz / per_n),
            "torque": (tx / per_nm, ty / per_nm, tz / per_nm),
            "overload": bool(status & od.FT_STATUS_OVERLOAD), "tared": bool(status & od.FT_STATUS_TARED)}
        return state


DRIVERS = {"joint_drive": JointDriver, "end_effector": EndEffectorDriver, "ft_sensor": FtDriver}


def _mapped_ref(ref: str | None, mapped: set[tuple[int, int]]) -> tuple[int, int] | None:
    obj = parse_object_ref(ref) if ref else None
    return obj if obj in mapped else None


def _clamp32(value: int) -> int:
    return max(_I32_MIN, min(_I32_MAX, value))


__all__ = ["EeCommand", "EeState", "JointState", "EndEffectorState", "FtState", "JointDriver",
           "EndEffectorDriver", "FtDriver", "DRIVERS"]
