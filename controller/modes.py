"""Motion modes: each answers one `update(t, measurement)` per cycle with a `ModeOutput`.

Planned modes only sample plans made when the command was accepted (Ruckig joint moves,
resolved Cartesian paths), so nothing inside a cycle can fail to plan or take long. Reactive
modes (closed-loop approach, impedance, the ORU task flow) compute from this cycle's
measurement; when one can no longer go on safely its output carries the failure and the core
makes a protective stop.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from spacearm.controller.cycle import EndEffectorCommand, Finding, Measurement, ModeOutput, hold
from spacearm.controller.planning.joint_move import JointSetpoint


class Plan(Protocol):
    duration: float

    def sample(self, t: float) -> JointSetpoint: ...


class ModeBase:
    """The shape most modes share: `update` advances the mode by one cycle (`_next_setpoint`, the only
    method that changes state) and reads the rest of its answer from side-effect-free queries."""
    moving = True
    start = 0.0
    _failure: Finding | None = None

    def update(self, t: float, m: Measurement) -> ModeOutput:
        setpoint = self._next_setpoint(t, m)
        return ModeOutput(setpoint, self._end_effector_command(), self._failure, self._finished(t), self._progress(t))

    def _next_setpoint(self, t: float, m: Measurement) -> JointSetpoint:
        raise NotImplementedError

    def _end_effector_command(self) -> EndEffectorCommand | None:
        return None

    def _finished(self, t: float) -> bool:
        return False

    def _progress(self, t: float) -> float:
        return 1.0 if self._finished(t) else 0.0


@dataclass
class HoldMode(ModeBase):
    """Hold a fixed joint position (drives enabled, servo active)."""
    q: np.ndarray
    name: str = "hold"
    moving = False

    def _next_setpoint(self, t: float, m: Measurement | None = None) -> JointSetpoint:
        return hold(self.q)

    def _progress(self, t: float) -> float:
        return 1.0


@dataclass
class PlannedMode(ModeBase):
    """Play back a plan that started at controller time `start`."""
    name: str            # "jog", "move_joints", "move_pose", ...
    plan: Plan
    start: float
    description: str = ""

    def _next_setpoint(self, t: float, m: Measurement | None = None) -> JointSetpoint:
        return self.plan.sample(t - self.start)

    def _finished(self, t: float) -> bool:
        return t - self.start >= self.plan.duration

    def _progress(self, t: float) -> float:
        if self.plan.duration <= 0:
            return 1.0
        return float(np.clip((t - self.start) / self.plan.duration, 0.0, 1.0))
