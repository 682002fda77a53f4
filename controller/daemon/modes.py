"""Motion modes: each gives the joint setpoint (and device commands) for one cycle.

Every mode follows the `Mode` protocol. Planned modes only sample plans made when the
command was accepted (Ruckig joint moves, resolved Cartesian paths), so nothing inside a
cycle can fail to plan or take long. Reactive modes (closed-loop approach, impedance, the
ORU task flow) compute from this cycle's measurement; when one can no longer go on safely
it says so through `failure()` and the core makes a protective stop.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from spacearm.controller.cycle import Measurement
from spacearm.controller.daemon.supervision import Finding
from spacearm.controller.planning.joint_move import JointSetpoint


class Plan(Protocol):
    duration: float

    def sample(self, t: float) -> JointSetpoint: ...


class Mode(Protocol):
    name: str
    start: float        # controller motion time the mode started at (set by the core)
    moving: bool        # True: motion supervision (following error) applies

    def setpoint(self, t: float, m: Measurement) -> JointSetpoint: ...

    def finished(self, t: float) -> bool: ...

    def progress(self, t: float) -> float: ...

    def failure(self) -> Finding | None: ...

    def device_commands(self) -> dict:
        """Non-joint commands for this cycle, e.g. {"end_effector": EeCommand.CLAMP}."""
        ...


class ModeBase:
    """Defaults for the optional parts of the protocol."""
    moving = True
    start = 0.0

    def failure(self) -> Finding | None:
        return None

    def device_commands(self) -> dict:
        return {}


@dataclass
class HoldMode(ModeBase):
    """Hold a fixed joint position (drives enabled, servo active)."""
    q: np.ndarray
    name: str = "hold"
    moving = False

    def setpoint(self, t: float, m: Measurement | None = None) -> JointSetpoint:
        zeros = np.zeros_like(self.q)
        return JointSetpoint(self.q, zeros, zeros)

    def finished(self, t: float) -> bool:
        return False

    def progress(self, t: float) -> float:
        return 1.0


@dataclass
class PlannedMode(ModeBase):
    """Play back a plan that started at controller time `start`."""
    name: str            # "jog", "move_joints", "move_pose", ...
    plan: Plan
    start: float
    description: str = ""

    def setpoint(self, t: float, m: Measurement | None = None) -> JointSetpoint:
        return self.plan.sample(t - self.start)

    def finished(self, t: float) -> bool:
        return t - self.start >= self.plan.duration

    def progress(self, t: float) -> float:
        if self.plan.duration <= 0:
            return 1.0
        return float(np.clip((t - self.start) / self.plan.duration, 0.0, 1.0))
