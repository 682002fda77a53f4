"""The kinds of subtask in Table 1, each a small Mode-like step the task runner drives.

A step is begun with the joint target the arm holds (the last command) and then sampled
every cycle with the runner's own clock (which stops while paused). Steps never block the
cycle: free motions are planned on a worker thread while the arm holds still.
"""
from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from spacearm.controller.daemon.modes import Mode
from spacearm.controller.cycle import Measurement
from spacearm.controller.daemon.supervision import Finding
from spacearm.controller.impedance.config import ImpedanceParams
from spacearm.controller.impedance.mode import ContactTask, ImpedanceMode
from spacearm.controller.planning.joint_move import JointSetpoint
from spacearm.base.canopen.od import EeCommand

_planner_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="oru-plan")


def hold(q: np.ndarray) -> JointSetpoint:
    zeros = np.zeros_like(q)
    return JointSetpoint(q.copy(), zeros, zeros)


@dataclass
class Step:
    stage: int              # 0-based stage index
    number: int             # Table 1 subtask number, 1..13
    title: str
    algorithm: str
    q_hold: np.ndarray = field(default=None, repr=False)   # type: ignore[assignment]
    started_at: float = 0.0
    notes: list[str] = field(default_factory=list)
    _failure: Finding | None = None

    def begin(self, q: np.ndarray, t: float) -> None:
        self.q_hold = np.asarray(q, float).copy()
        self.started_at = t

    def setpoint(self, t: float, m: Measurement) -> JointSetpoint:
        return hold(self.q_hold)

    def finished(self, t: float) -> bool:
        return True

    def progress(self, t: float) -> float:
        return 1.0 if self.finished(t) else 0.0

    def failure(self) -> Finding | None:
        return self._failure

    def device_commands(self) -> dict:
        return {}

    def fail(self, code: str, message: str) -> None:
        self._failure = Finding(code, f"stage {self.stage + 1} subtask {self.number} ({self.title}): {message}")

    def _follow(self, mode, t: float, m: Measurement) -> JointSetpoint:
        """The mode's setpoint; its first failure becomes this step's."""
        sp = mode.setpoint(t, m)
        failure = mode.failure()
        if failure is not None and self._failure is None:
            self.fail(failure.code, failure.message)
        return sp


@dataclass
class ModeStep(Step):
    """A step that runs a daemon Mode, made by `make(q, t)` (possibly on the planning thread)."""
    make: Callable[[np.ndarray], Any] = None          # type: ignore[assignment]
    wrap: Callable[[Any, float], Mode] | None = None   # plan -> Mode (planned steps)
    background: bool = False
    mode: Mode | None = None
    _future: Future | None = None

    def begin(self, q: np.ndarray, t: float) -> None:
        super().begin(q, t)
        if self.background:
            self._future = _planner_pool.submit(self.make, self.q_hold)
        else:
            self._start(self.make(self.q_hold), t)

    def _start(self, made: Any, t: float) -> None:
        mode = self.wrap(made, t) if self.wrap is not None else made
        mode.start = t
        self.mode = mode

    def setpoint(self, t: float, m: Measurement) -> JointSetpoint:
        if self.mode is None:
            future = self._future
            if future is None or not future.done():
                return hold(self.q_hold)
            try:
                self._start(future.result(), t)
            except Exception as exc:   # planning refused: unreachable, limits, ...
                self.fail("planning_failed", str(exc))
                return hold(self.q_hold)
        return self._follow(self.mode, t, m)

    def finished(self, t: float) -> bool:
        return self.mode is not None and self._failure is None and self.mode.finished(t)

    def progress(self, t: float) -> float:
        return 0.0 if self.mode is None else float(self.mode.progress(t))

    def device_commands(self) -> dict:
        return self.mode.device_commands() if self.mode is not None else {}


@dataclass
class EndEffectorStep(Step):
    """Command the end effector and wait for its state (clamp+lock -> locked, release -> open)."""
    command: EeCommand = EeCommand.NONE
    expect: str = "locked"
    timeout: float = 10.0
    _sent: bool = False
    _done: bool = False

    def setpoint(self, t: float, m: Measurement) -> JointSetpoint:
        if self._sent and not self._done and self._failure is None:
            if m.end_effector == "fault":
                self.fail("end_effector_fault", f"end effector reports a fault while waiting for {self.expect!r} "
                          "(capture not confirmed, jam or screw torque)")
            elif m.end_effector == self.expect:
                self._done = True
            elif t - self.started_at > self.timeout:
                self.fail("end_effector_timeout", f"end effector still {m.end_effector!r} after "
                          f"{self.timeout:.0f} s (expected {self.expect!r})")
        return hold(self.q_hold)

    def device_commands(self) -> dict:
        if self._sent:
            return {}
        self._sent = True
        return {"end_effector": self.command}

    def finished(self, t: float) -> bool:
        return self._done


@dataclass
class LatchStep(Step):
    """Drive the store's connection mechanism through the end effector's screw drive, then wait
    its travel time (the mechanism has no feedback on this bus: an unreleased latch shows up as
    the extraction's force limit)."""
    command: EeCommand = EeCommand.NONE
    wait: float = 1.5
    _sent: bool = False

    def device_commands(self) -> dict:
        if self._sent:
            return {}
        self._sent = True
        return {"end_effector": self.command}

    def finished(self, t: float) -> bool:
        return self._sent and t - self.started_at >= self.wait

    def progress(self, t: float) -> float:
        return min(1.0, (t - self.started_at) / self.wait)


@dataclass
class ContactStep(Step):
    """Impedance control (capture, extraction, insertion, withdrawal)."""
    model: Any = None
    params: ImpedanceParams | None = None
    task_of: Callable[[], ContactTask] = None          # type: ignore[assignment]
    mode: ImpedanceMode | None = None

    def begin(self, q: np.ndarray, t: float) -> None:
        super().begin(q, t)
        self.mode = ImpedanceMode(self.model, self.params, self.task_of(), self.q_hold, self.title)

    def setpoint(self, t: float, m: Measurement) -> JointSetpoint:
        return self._follow(self.mode, t, m)

    def finished(self, t: float) -> bool:
        return self._failure is None and self.mode.finished(t)

    def progress(self, t: float) -> float:
        return self.mode.progress(t)
