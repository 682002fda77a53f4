"""Motion modes: each gives the joint setpoint for a cycle from its own plan.

Modes only sample plans made when the command was accepted (Ruckig joint moves,
resolved Cartesian paths), so nothing inside a cycle can fail to plan or take long.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from controller.planning.joint_move import JointSetpoint


class Plan(Protocol):
    duration: float

    def sample(self, t: float) -> JointSetpoint: ...


@dataclass
class HoldMode:
    """Hold a fixed joint position (drives enabled, servo active)."""
    q: np.ndarray
    name: str = "hold"

    def setpoint(self, t: float) -> JointSetpoint:
        zeros = np.zeros_like(self.q)
        return JointSetpoint(self.q, zeros, zeros)

    def finished(self, t: float) -> bool:
        return False

    def progress(self, t: float) -> float:
        return 1.0


@dataclass
class PlannedMode:
    """Play back a plan that started at controller time `start`."""
    name: str            # "jog", "move_joints", "move_pose", ...
    plan: Plan
    start: float
    description: str = ""

    def setpoint(self, t: float) -> JointSetpoint:
        return self.plan.sample(t - self.start)

    def finished(self, t: float) -> bool:
        return t - self.start >= self.plan.duration

    def progress(self, t: float) -> float:
        if self.plan.duration <= 0:
            return 1.0
        return float(np.clip((t - self.start) / self.plan.duration, 0.0, 1.0))
