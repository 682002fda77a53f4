"""Every reason the arm stops, and how it stops: the one table (README "Stops" prints it).

Categories in the sense of IEC 60204-1: 0 power off at once and brakes; 1 a controlled stop,
then power off and brakes; 2 a controlled stop with power kept on. Who decelerates: the
controller's planner (controller/planning/stop_trajectory.py: from the measured state, all
joints on one path, at the arm file's acceleration limits), or each drive on its own with
CiA 402 quick stop (605Ah = 2 on the 6085h ramp, which bring-up sets to the arm file's
acceleration, controller/daemon/hardware.py) or its fault reaction (605Eh = 2, same ramp).

The stop is supervised as it runs (StopMonitor): a joint that speeds up by more than 10 % of
its limit, or is not at rest STOP_GRACE_CYCLES after v/a, or a drive still in operation
QUICK_STOP_ACK_CYCLES after the quick-stop request, escalates the stop to category 0.
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np

from spacearm.controller.cycle import Finding, FindingCode, Measurement

QUICK_STOP_ACK_CYCLES = 5     # a drive still in operation enabled this many cycles after the request ignores it
STOP_GRACE_CYCLES = 10        # beyond v/a before a joint still moving is a stop overrun
SPEED_UP_TOLERANCE = 0.10     # of the joint's limit: the drive's reported speed, with its noise
RESTING_SPEED = 0.02          # of the joint's limit: at rest


class Decelerator(str, Enum):
    PLANNER = "controller planner"
    QUICK_STOP = "drive quick stop"
    FAULT_REACTION = "drive fault reaction"
    NONE = "nobody (power off)"


class DriveRequest(str, Enum):
    """What the hardware asks of the drives once the command no longer enables them."""
    QUICK_STOP = "quick_stop"     # controlword quick stop: 605Ah's ramp, then power off and brake
    DISABLE = "disable"           # controlword disable voltage: power off now, brake


@dataclass(frozen=True)
class StopPolicy:
    category: int
    decelerator: Decelerator
    deceleration: str
    final: str

    @property
    def rank(self) -> int:
        """Stronger stops replace weaker ones while stopping: planner < drives < power off."""
        return {Decelerator.PLANNER: 0, Decelerator.QUICK_STOP: 1, Decelerator.FAULT_REACTION: 1,
                Decelerator.NONE: 2}[self.decelerator]


_ACCEL = "the arm file's acceleration limit per joint"
_OFF = "switch on disabled, brakes on"
PLANNED = StopPolicy(1, Decelerator.PLANNER, _ACCEL + " (one path, reached in one cycle)",
                     "quick stop at rest, then " + _OFF)
DRIVES = StopPolicy(1, Decelerator.QUICK_STOP, "6085h = " + _ACCEL, _OFF)
FAULTED = StopPolicy(1, Decelerator.FAULT_REACTION, "6085h = " + _ACCEL + " (605Eh = 2); the other drives: quick stop",
                     "the drive in fault, brake on; the others " + _OFF)
MASTER_LOST = StopPolicy(1, Decelerator.FAULT_REACTION, "6085h = " + _ACCEL + " (605Eh = 2), each drive on its own",
                         "every drive in fault, brakes on; `reset` once a daemon is back")
DISABLE = StopPolicy(1, Decelerator.PLANNER, _ACCEL + " (one path, reached in one cycle)",
                     "disable voltage at rest: switch on disabled, brakes on; state `disabled`, no reset needed")
POWER_OFF = StopPolicy(0, Decelerator.NONE, "none: brakes", "switch on disabled, brakes on")

# reason -> policy; the reasons are the stop codes (controller/cycle.py) and two the drives
# act on by themselves, without the controller
STOPS: dict[str, StopPolicy] = {
    FindingCode.OPERATOR_STOP: PLANNED,           # console, web console, API `stop`
    FindingCode.COMMAND_WATCHDOG: PLANNED,        # jogging console silent or gone, lease holder gone
    FindingCode.SHUTDOWN: PLANNED,                # the daemon's SIGINT/SIGTERM
    "disable": DISABLE,                           # the `disable` command while a motion runs (not a stop)
    FindingCode.FOLLOWING_ERROR: PLANNED,
    FindingCode.POSITION_LIMIT: PLANNED,
    FindingCode.VELOCITY_LIMIT: PLANNED,
    FindingCode.ENABLE_TIMEOUT: PLANNED,
    FindingCode.FT_OVERLOAD: PLANNED,
    FindingCode.FT_LIMIT: PLANNED,
    FindingCode.FT_JUMP: PLANNED,
    FindingCode.FT_FROZEN: PLANNED,
    FindingCode.CONTACT_FORCE_LIMIT: PLANNED,
    FindingCode.CONTACT_MISSING: PLANNED,
    FindingCode.JAMMED: PLANNED,
    FindingCode.VISION_LOST: PLANNED,             # only where a mode gives up; an approach holds (category 2)
    FindingCode.CAMERA_STOPPED: PLANNED,
    FindingCode.FRAME_STALE: PLANNED,
    FindingCode.TOO_FAR: PLANNED,
    FindingCode.ERROR_GROWS: PLANNED,
    FindingCode.END_EFFECTOR_FAULT: PLANNED,
    FindingCode.END_EFFECTOR_TIMEOUT: PLANNED,
    FindingCode.PLANNING_FAILED: PLANNED,
    FindingCode.HEARTBEAT_LOST: DRIVES,           # a node's data cannot be trusted: each drive stops itself
    FindingCode.PDO_MISSING: DRIVES,
    FindingCode.BOOTUP: DRIVES,
    FindingCode.EMCY: DRIVES,
    FindingCode.FAULT: FAULTED,                   # a drive's own fault
    "master_heartbeat_lost": MASTER_LOST,             # at the drive (1016h): its fault reaction, no controller
    FindingCode.QUICK_STOP_IGNORED: POWER_OFF,
    FindingCode.STOP_OVERRUN: POWER_OFF,
}


def stop_policy(code: str) -> StopPolicy:
    return STOPS.get(code, PLANNED)


def stops_table() -> str:
    """The table as README markdown, one row per policy with every reason that takes it."""
    lines = ["| reasons (stop codes) | category | who decelerates | deceleration | drives and brakes after |",
             "| --- | --- | --- | --- | --- |"]
    policies = list(dict.fromkeys(STOPS.values()))
    for p in policies:
        reasons = ", ".join(f"`{r}`" for r, q in STOPS.items() if q is p)
        lines.append(f"| {reasons} | {p.category} | {p.decelerator.value} | {p.deceleration} | {p.final} |")
    return "\n".join(lines)


class StopMonitor:
    """Watches a stop from its first cycle to rest; answers a finding when it must become category 0."""

    def __init__(self, joint_names: list[str], v_max: np.ndarray, a_max: np.ndarray, period: float):
        self.names = joint_names
        self.v_max = np.asarray(v_max, float)
        self.a_max = np.asarray(a_max, float)
        self.period = period
        self.active = False

    def start(self, m: Measurement) -> None:
        self.active = True
        self.v_stop = np.abs(m.dq)
        self.deadline = m.time + float(np.max(self.v_stop / self.a_max)) + STOP_GRACE_CYCLES * self.period
        self.quick_stop_at: float | None = None

    def quick_stop_requested(self, t: float) -> None:
        if self.active and self.quick_stop_at is None:
            self.quick_stop_at = t

    def end(self) -> None:
        self.active = False

    def check(self, m: Measurement) -> Finding | None:
        if not self.active:
            return None
        speed = np.abs(m.dq)
        faster = np.flatnonzero(speed > self.v_stop + SPEED_UP_TOLERANCE * self.v_max)
        if faster.size:
            i = int(faster[0])
            return Finding(FindingCode.STOP_OVERRUN, f"{self.names[i]}: speed {speed[i]:.4f} rad/s while stopping, "
                           f"above {self.v_stop[i]:.4f} at the stop", joint=self.names[i])
        moving = np.flatnonzero(speed > RESTING_SPEED * self.v_max)
        if m.time > self.deadline + 1e-9 and moving.size:
            i = int(moving[0])
            return Finding(FindingCode.STOP_OVERRUN, f"{self.names[i]}: still moving at {speed[i]:.4f} rad/s "
                           f"{STOP_GRACE_CYCLES} cycles after it should be at rest", joint=self.names[i])
        if self.quick_stop_at is not None and m.time - self.quick_stop_at >= QUICK_STOP_ACK_CYCLES * self.period - 1e-9:
            enabled = np.flatnonzero(m.joints_enabled)
            if enabled.size:
                i = int(enabled[0])
                return Finding(FindingCode.QUICK_STOP_IGNORED, f"{self.names[i]}: still in operation "
                               f"{QUICK_STOP_ACK_CYCLES} cycles after the quick stop: powered off, brakes on",
                               joint=self.names[i])
        return None


if __name__ == "__main__":
    print(stops_table())
