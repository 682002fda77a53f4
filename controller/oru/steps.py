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

from spacearm.controller.cycle import EndEffectorCommand, EndEffectorState, Finding, FindingCode, Measurement, Mode, ModeOutput, hold
from spacearm.controller.impedance.config import ImpedanceParams
from spacearm.controller.impedance.mode import ContactTask, ImpedanceMode

_planner_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="oru-plan")


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

    def update(self, t: float, m: Measurement) -> ModeOutput:
        """Advance the step by one cycle (the runner's clock t) and answer as a mode does."""
        return ModeOutput(hold(self.q_hold), failure=self._failure, finished=self._failure is None, progress=1.0)

    def fail(self, code: FindingCode, message: str) -> None:
        self._failure = Finding(code, f"stage {self.stage + 1} subtask {self.number} ({self.title}): {message}")

    def _follow(self, mode: Mode, t: float, m: Measurement) -> ModeOutput:
        """The mode's output, with its first failure adopted as this step's."""
        out = mode.update(t, m)
        if out.failure is not None and self._failure is None:
            self.fail(out.failure.code, out.failure.message)
        return ModeOutput(out.setpoint, out.end_effector, self._failure, out.finished and self._failure is None,
                          out.progress)


@dataclass
class ModeStep(Step):
    """A step that runs a daemon Mode, made by `make(q, t)` (possibly on the planning thread)."""
    make: Callable[[np.ndarray], Any] = None          # type: ignore[assignment]
    wrap: Callable[[Any, float], Mode] | None = None   # plan -> Mode (planned steps)
    background: bool = False
    retry_codes: frozenset = frozenset()               # failures the runner may retry (closed-loop approach)
    mode: Mode | None = None
    _future: Future | None = None

    def reset(self) -> None:
        """Forget the attempt (mode, failure) so that begin() starts a new one."""
        self._failure, self.mode, self._future = None, None, None

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

    def update(self, t: float, m: Measurement) -> ModeOutput:
        if self.mode is None:
            future = self._future
            if future is None or not future.done():
                return ModeOutput(hold(self.q_hold))
            try:
                self._start(future.result(), t)
            except Exception as exc:   # planning refused: unreachable, limits, ...
                self.fail(FindingCode.PLANNING_FAILED, str(exc))
                return ModeOutput(hold(self.q_hold), failure=self._failure)
        return self._follow(self.mode, t, m)


@dataclass
class EndEffectorStep(Step):
    """Command the end effector and wait for its state (clamp+lock -> locked, release -> open)."""
    command: EndEffectorCommand = EndEffectorCommand.CLAMP
    expect: EndEffectorState = EndEffectorState.LOCKED
    timeout: float = 10.0
    _sent: bool = False
    _done: bool = False

    def update(self, t: float, m: Measurement) -> ModeOutput:
        if self._sent and not self._done and self._failure is None:
            if m.end_effector == EndEffectorState.FAULT:
                self.fail(FindingCode.END_EFFECTOR_FAULT, f"end effector reports a fault while waiting for "
                          f"{self.expect.value!r} (capture not confirmed, jam or screw torque)")
            elif m.end_effector == self.expect:
                self._done = True
            elif t - self.started_at > self.timeout:
                self.fail(FindingCode.END_EFFECTOR_TIMEOUT, f"end effector still {str(m.end_effector)!r} after "
                          f"{self.timeout:.0f} s (expected {self.expect.value!r})")
        done = self._done
        command, self._sent = (None if self._sent else self.command), True
        return ModeOutput(hold(self.q_hold), command, self._failure, done, 1.0 if done else 0.0)


@dataclass
class LatchStep(Step):
    """Drive the store's connection mechanism through the end effector's screw drive, then wait
    its travel time (the mechanism has no feedback on this bus: an unreleased latch shows up as
    the extraction's force limit)."""
    command: EndEffectorCommand = EndEffectorCommand.LATCH_LOCK
    wait: float = 1.5
    _sent: bool = False

    def update(self, t: float, m: Measurement) -> ModeOutput:
        done = self._sent and t - self.started_at >= self.wait
        command, self._sent = (None if self._sent else self.command), True
        return ModeOutput(hold(self.q_hold), command, self._failure, done,
                          min(1.0, (t - self.started_at) / self.wait))


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

    def update(self, t: float, m: Measurement, rate: float = 1.0) -> ModeOutput:
        """`rate`: the runner clock's rate; 0 while paused (the admittance holds the contact)."""
        self.mode.rate = rate
        return self._follow(self.mode, t, m)
