"""The control cycle's vocabulary: what was measured, what is commanded, what a mode answers,
and the codes everything is named by.

The hardware interface turns CANopen traffic into a `Measurement` each cycle and a `Command`
back into RPDOs; the modes and the core between them work on these values only. The enums are
`str` enums whose values are the words the console, the recordings and the tests have always
shown, so a status line reads the same and code branches on the member, never on text.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Protocol

import numpy as np

from spacearm.controller.planning.joint_move import JointSetpoint


class MachineState(str, Enum):
    """disabled -> enabling -> enabled -> disabled; any -> stopped --reset--> disabled."""
    DISABLED = "disabled"
    ENABLING = "enabling"
    ENABLED = "enabled"
    STOPPED = "stopped"        # protective stop: brakes on, motion refused until reset

    def __str__(self) -> str:
        return self.value


class EndEffectorState(str, Enum):
    """What the end effector reports (the controller's side of 2101h)."""
    NONE = "none"              # no end effector on this bus
    UNKNOWN = "unknown"
    OPEN = "open"
    CLOSING = "closing"
    LOCKING = "locking"
    LOCKED = "locked"          # clamped and locked
    UNLOCKING = "unlocking"
    OPENING = "opening"
    STOPPED = "stopped"
    FAULT = "fault"

    def __str__(self) -> str:
        return self.value


class EndEffectorCommand(str, Enum):
    """What a mode may ask of the end effector this cycle (the hardware maps it to 2100h)."""
    CLAMP = "clamp"            # close the grip, then screw until locked
    RELEASE = "release"        # unscrew, then open the grip
    STOP = "stop"
    FAULT_RESET = "fault_reset"
    LATCH_UNLOCK = "latch_unlock"
    LATCH_LOCK = "latch_lock"


class FindingCode(str, Enum):
    """Why the controller stopped (or a mode gave up): stable codes for consoles and tests."""
    # device reports and missing data
    HEARTBEAT_LOST = "heartbeat_lost"
    EMCY = "emcy"
    FAULT = "fault"                        # a drive in fault
    BOOTUP = "bootup"                      # a node restarted
    PDO_MISSING = "pdo_missing"
    LATE_CYCLE = "late_cycle"              # not a stop: the controller itself was starved (event only)
    HOST_STALL = "host_stall"              # not a stop: the host held a vCPU the nodes run on (event only)
    LINE_SWITCH = "line_switch"            # not a stop: the bus moved to its other line (event only)
    LINE_SWITCH_COMPLETE = "line_switch_complete"   # every node heard on the new line (event only)
    BUS_LINES_LOST = "bus_lines_lost"      # both lines of a redundant pair silent
    # motion supervision
    POSITION_LIMIT = "position_limit"
    VELOCITY_LIMIT = "velocity_limit"
    FOLLOWING_ERROR = "following_error"
    ENABLE_TIMEOUT = "enable_timeout"
    # force/torque sensor
    FT_OVERLOAD = "ft_overload"
    FT_LIMIT = "ft_limit"
    FT_JUMP = "ft_jump"
    FT_FROZEN = "ft_frozen"
    # operators and consoles
    OPERATOR_STOP = "operator_stop"
    COMMAND_WATCHDOG = "command_watchdog"
    SHUTDOWN = "shutdown"                  # the daemon was told to end (SIGINT/SIGTERM)
    # the stop itself (controller/daemon/stops.py): escalated to power off and brakes
    QUICK_STOP_IGNORED = "quick_stop_ignored"   # a drive still in operation after the quick-stop request
    STOP_OVERRUN = "stop_overrun"          # a joint sped up while stopping, or is not at rest in time
    # modes that can no longer go on safely
    CONTACT_FORCE_LIMIT = "contact_force_limit"
    CONTACT_MISSING = "contact_missing"
    JAMMED = "jammed"
    VISION_LOST = "vision_lost"            # frames arrive, the marker is not measured in them
    CAMERA_STOPPED = "camera_stopped"      # no new frame at all
    FRAME_STALE = "frame_stale"            # results arrive, but from exposures too old to steer by
    TOO_FAR = "too_far"
    ERROR_GROWS = "error_grows"
    END_EFFECTOR_FAULT = "end_effector_fault"
    END_EFFECTOR_TIMEOUT = "end_effector_timeout"
    PLANNING_FAILED = "planning_failed"

    def __str__(self) -> str:
        return self.value


# codes recorded as events with their code, never a stop
EVENT_ONLY = frozenset({FindingCode.LATE_CYCLE, FindingCode.HOST_STALL, FindingCode.LINE_SWITCH,
                        FindingCode.LINE_SWITCH_COMPLETE})

# codes a node's own report or silence produces: watched even while the arm is disabled
NODE_FINDINGS = frozenset({FindingCode.HEARTBEAT_LOST, FindingCode.EMCY, FindingCode.BOOTUP,
                           FindingCode.BUS_LINES_LOST, FindingCode.PDO_MISSING, FindingCode.FT_FROZEN})


@dataclass(frozen=True)
class Finding:
    """A reason to stop: a stable code, what a person needs to know, and what it concerns."""
    code: FindingCode
    message: str
    node: str | None = None        # the CANopen node concerned, if one
    joint: str | None = None       # the joint concerned, if one

    def __post_init__(self) -> None:
        object.__setattr__(self, "code", FindingCode(self.code))   # a bad code fails here, not in a console

    def __str__(self) -> str:
        return self.message

    def as_dict(self) -> dict:
        return {"code": self.code.value, "message": self.message, "node": self.node, "joint": self.joint}


@dataclass(frozen=True)
class DeviceEvent:
    """Something a node reported or failed to report (heartbeat loss, EMCY, boot-up, fault)."""
    node: str
    kind: FindingCode              # HEARTBEAT_LOST | EMCY | BOOTUP | FAULT
    detail: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", FindingCode(self.kind))


@dataclass(frozen=True)
class Measurement:
    time: float                  # s, controller time of this cycle
    sync_counter: int
    q: np.ndarray                # rad (m for a prismatic joint)
    dq: np.ndarray               # rad/s
    tau: np.ndarray              # N m
    joints_enabled: np.ndarray   # bool per joint: drive in "operation enabled"
    joints_faulted: np.ndarray   # bool per joint
    wrench: np.ndarray           # N, N m: fx fy fz tx ty tz (sensor frame)
    wrench_overload: bool = False
    end_effector: EndEffectorState = EndEffectorState.UNKNOWN
    events: tuple[DeviceEvent, ...] = ()
    missing: tuple[str, ...] = ()   # nodes whose PDOs did not arrive this cycle
    late: bool = False              # this cycle's own I/O ran late (controller starved): missing data is no evidence
    bridged: bool = False           # missing data of a bus line switch under way (bounded): not node loss
    # the host held one of this machine's vCPUs in this cycle's gap (base/runtime/host_cpus.py;
    # a gap's first complete cycle may be the one that shows it): missing data is the stall of
    # the nodes' host process, counted against them only after a bounded excuse
    host_stalled: bool = False
    # nodes missing at the last cycle's read whose data came later in that period: slow, not silent
    answered_late: tuple[str, ...] = ()
    # bool per joint: drive powered (operation enabled, quick stop or fault reaction active);
    # None: as joints_enabled
    joints_powered: np.ndarray | None = None


def built(cls, values: dict):
    """cls(**values) for a frozen dataclass made every cycle (Measurement), `values` naming every
    field in the class's order: the same object without the generated __init__'s
    object.__setattr__ per field (issue 35: most of a Measurement's cost)."""
    obj = object.__new__(cls)
    obj.__dict__.update(values)
    return obj


@dataclass(frozen=True)
class Command:
    """What the cycle writes: the joints' CSP targets and, at most once, an end-effector command."""
    q: np.ndarray                # rad, CSP target
    dq: np.ndarray = field(default_factory=lambda: np.zeros(0))  # rad/s feed-forward
    enable: bool = True          # False: drives to quick stop and brakes
    end_effector: EndEffectorCommand | None = None


@dataclass(frozen=True)
class ModeOutput:
    """A mode's whole answer for one cycle (as Ruckig's OutputParameter): nothing else about the
    cycle is asked of it, and asking changes nothing."""
    setpoint: JointSetpoint
    end_effector: EndEffectorCommand | None = None
    failure: Finding | None = None   # the mode cannot go on safely: the core stops the arm
    finished: bool = False
    progress: float = 0.0            # 0..1


def hold(q: np.ndarray) -> JointSetpoint:
    """Stand still at q."""
    zeros = np.zeros_like(q)
    return JointSetpoint(np.asarray(q, float).copy(), zeros, zeros)


class Mode(Protocol):
    """One motion mode: `update` is called once per cycle with the motion clock and this cycle's
    measurement; it advances the mode by one cycle and returns its output."""
    name: str
    description: str
    start: float        # motion time the mode started at (set by the core)
    moving: bool        # True: motion supervision (following error) applies

    def update(self, t: float, m: Measurement) -> ModeOutput: ...
