"""The controller's decision logic for one cycle, free of I/O so it can be tested alone.

States:  disabled -> enabling -> enabled (hold or a motion mode) -> disabled
                       any state -> stopped (protective stop) --reset--> disabled
A protective stop stops as its reason's policy says (controller/daemon/stops.py): the
planner's stop from the measured state while the drives stay enabled, then a quick stop at
rest; or the drives' own quick stop; or power off. Supervised until at rest.
`update(measurement)` is called once per cycle and returns the command to write.
Console commands arrive through `submit()` from other threads and are applied at the
start of the next cycle, so the cycle alone changes controller state.
"""
from __future__ import annotations

import queue
import threading
from concurrent.futures import Future
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from spacearm.controller.cycle import (EVENT_ONLY, NODE_FINDINGS, Command, Finding, FindingCode, MachineState,
                                       Measurement, Mode, ModeOutput, built)
from spacearm.controller.daemon.api_errors import CodedError, ErrorCode
from spacearm.controller.daemon.stops import DriveRequest, StopMonitor, StopPolicy, stop_policy
from spacearm.controller.daemon.supervision import Supervisor
from spacearm.controller.modes import HoldMode
from spacearm.controller.planning.errors import PlanningError
from spacearm.controller.planning.joint_move import JointSetpoint
from spacearm.controller.planning.stop_trajectory import StopTrajectory

ENABLE_TIMEOUT = 2.0  # s for every drive to reach "operation enabled"
# The states as the cycle tests them (update, _command): module names, not the enum class's
# member lookup (~0.15 us each, a dozen a cycle; issue 35). The cycle's Commands are built
# without the frozen dataclass's __init__ (controller/cycle.py built): the same fields.
_ENABLING, _ENABLED, _STOPPED = MachineState.ENABLING, MachineState.ENABLED, MachineState.STOPPED
_ENABLED_OR_ENABLING, _STOPPED_OR_ENABLED = (_ENABLED, _ENABLING), (_STOPPED, _ENABLED)


def _zeros_as(q: np.ndarray) -> np.ndarray:
    """np.zeros_like(q) for the cycle's 1-D joint arrays: the same zeros of q's shape and dtype,
    without zeros_like's Python-level dispatch (~1 us a cycle, issue 35); anything else (a list,
    a subclass) through zeros_like itself."""
    return np.zeros(q.shape, q.dtype) if type(q) is np.ndarray else np.zeros_like(q)


class CommandRefused(CodedError):
    """The command is valid in form but not now (wrong state, unreachable target, ...)."""
    default_code = ErrorCode.NOT_ENABLED


@dataclass
class Event:
    time: float
    kind: str
    message: str
    finding: Finding | None = None    # the finding behind a protective stop or an extra finding

    def as_dict(self) -> dict:
        entry = {"t": self.time, "kind": self.kind, "message": self.message}
        if self.finding is not None:
            entry |= {k: v for k, v in self.finding.as_dict().items() if v is not None and k != "message"}
        return entry


@dataclass
class _Pending:
    apply: Callable[[float, Measurement], Any]
    future: Future = field(default_factory=Future)


class ControllerCore:
    def __init__(self, supervisor: Supervisor, joint_names: list[str], period: float,
                 a_max: np.ndarray | None = None):
        self.supervisor = supervisor
        self.period = period
        # Without the joints' acceleration limits the controller cannot plan a stop: the
        # drives' quick stop makes every controlled stop.
        self.a_max = None if a_max is None else np.asarray(a_max, float)
        self.stop_monitor = StopMonitor(joint_names, supervisor.limits.v_max,
                                        self.a_max if self.a_max is not None else np.full(len(joint_names), np.inf),
                                        period)
        self.stop_policy: StopPolicy | None = None
        self.stopping: StopTrajectory | None = None     # the planner's stop while it runs
        self._stopping_since = 0.0
        self.drive_request = DriveRequest.QUICK_STOP     # what a disabling command asks of the drives
        self.last_setpoint: JointSetpoint | None = None
        # Motions are sampled on their own clock, one period per executed cycle: after an
        # overrun (skipped cycles) a motion continues where it was instead of jumping ahead.
        self.motion_time = 0.0
        # After a bus line switch (bridged cycles: the path waited, the drives held their last
        # target) the path's clock speeds back up from 0 to 1 within the joints' acceleration
        # limits: resumed at full rate it asked a held drive for its full path speed at once,
        # and the drive's catch-up overshot the velocity limit (seen over the loopback hub).
        self.resume_rate = 1.0
        self._resume_per_s = 0.0
        self._sampled_at = 0.0         # motion time of the last setpoint sent
        # Motion numbers let a console wait for *its* motion: started counts up when a motion
        # is accepted, finished is set when that motion ends normally.
        self.motions_started = 0
        self.motions_finished = 0
        self.joint_names = joint_names
        self.state = MachineState.DISABLED
        self.mode: Mode | None = None
        self.mode_output: ModeOutput | None = None   # the current mode's answer of the last cycle
        self.stop_reason: Finding | None = None
        self.events: list[Event] = []           # new events since the last drain
        self.last_target: np.ndarray | None = None
        self.last_measurement: Measurement | None = None
        self._enable_started = 0.0
        self._pending: "queue.Queue[_Pending]" = queue.Queue()
        # A daemon answers a command only once the cycle that took it has published its status:
        # a console that reads `status` right after "ok" sees its own command (a mode that
        # started, a state that changed), never the cycle before it.
        self.defer_answers = False
        self._answers: list[tuple[Future, Any, BaseException | None]] = []
        self._lock = threading.Lock()

    @property
    def state(self) -> MachineState:
        return self._state

    @state.setter
    def state(self, value: MachineState | str) -> None:
        self._state = MachineState(value)    # a misspelt state fails where it is set

    # ---- called from the API threads -------------------------------------------------
    def submit(self, apply: Callable[[float, Measurement], Any], timeout: float = 2.0) -> Any:
        """Run `apply(t, measurement)` at the start of the next cycle and return its result."""
        pending = _Pending(apply)
        self._pending.put(pending)
        return pending.future.result(timeout=timeout)

    @property
    def requests_waiting(self) -> bool:
        """An API thread waits for the next cycle to take its request (lockstep drivers cycle on it)."""
        return not self._pending.empty()

    def queue(self, apply: Callable[[float, Measurement], Any]) -> None:
        """Run `apply` at the start of the next cycle, nobody waiting for it (a stop sent while
        the drives are brought up, before the first cycle)."""
        self._pending.put(_Pending(apply))

    # ---- called by the cycle ----------------------------------------------------------
    def update(self, m: Measurement) -> Command:
        self.last_measurement = m
        self._apply_pending(m)
        for event in m.events:   # the controller's starvation, bus line switches: recorded with their code, not a stop
            if event.kind in EVENT_ONLY:
                self._event(m.time, event.kind.value, event.detail,
                            Finding(event.kind, event.detail, node=event.node or None))
        moving = self._state is _ENABLED and self.mode is not None and self.mode.moving
        if self._state in _ENABLED_OR_ENABLING:
            findings = self.supervisor.check(m, self.last_target, moving)
        else:
            # Disabled or stopped: still watch the nodes (and, stopping, the drives' faults),
            # but not motion-related limits.
            watched = NODE_FINDINGS | {FindingCode.FAULT} if self._state is _STOPPED else NODE_FINDINGS
            findings = [f for f in self.supervisor.check(m, None, False) if f.code in watched]
        if self._state is _STOPPED:
            overrun = self.stop_monitor.check(m)
            findings += [overrun] if overrun is not None else []
            for finding in findings:      # a stronger stop replaces the one running
                self._escalate(m.time, finding)
        elif findings:
            self.protective_stop(m.time, findings[0])
            for extra in findings[1:]:
                self._event(m.time, "finding", extra.message, extra)
        if self._state is _ENABLING:
            if np.all(m.joints_enabled):
                self.state = MachineState.ENABLED
                self._set_mode(HoldMode(m.q.copy()))
                self._event(m.time, "state", "all joints enabled")
            elif m.time - self._enable_started > ENABLE_TIMEOUT:
                slow = [n for n, ok in zip(self.joint_names, m.joints_enabled) if not ok]
                self.protective_stop(m.time, Finding(FindingCode.ENABLE_TIMEOUT,
                                     f"joints not enabled within {ENABLE_TIMEOUT:.0f} s: {', '.join(slow)}",
                                     joint=slow[0] if slow else None))
        command = self._command(m)
        if m.bridged:            # a bus line switch: the drives get nothing, so the path waits for them
            if self.resume_rate > 0.0:
                # it resumes at the last target sent (the one the drives hold), not a step beyond it
                self.motion_time = self._sampled_at
                self.resume_rate, self._resume_per_s = 0.0, self._resume_ramp()
        elif self.stopping is not None or self.resume_rate >= 1.0:
            self.motion_time += self.period
        else:
            self.resume_rate = min(1.0, self.resume_rate + self.period * self._resume_per_s)
            self.motion_time += self.period * self.resume_rate
        return command

    def _resume_ramp(self) -> float:
        """1/s the path's clock rate rises by after a bridged gap: the paused path velocity
        reached at the joints' acceleration limits (at once without limits or velocity)."""
        if self.last_setpoint is None or self.a_max is None:
            return float("inf")
        ramp = float(np.max(np.abs(self.last_setpoint.dq) / self.a_max, initial=0.0))
        return 1.0 / ramp if ramp > self.period else float("inf")

    def _command(self, m: Measurement) -> Command:
        if self.stopping is not None and self._state in _STOPPED_OR_ENABLED:
            command = self._stopping_command()
            if command is not None:
                return command
            if self._state is _ENABLED:       # a `disable` that waited for rest
                self.state = MachineState.DISABLED
                self._event(m.time, "state", "disabled at rest, brakes on")
        if self._state is _ENABLED and self.mode is not None:
            if m.bridged and self.last_setpoint is not None:
                # the drives hold the last target they got; resuming from it avoids a catch-up
                # faster than the joints' limits once the switch completes
                return Command(self.last_setpoint.q.copy(), _zeros_as(m.q), enable=True)
            mode = self.mode
            self._sampled_at = self.motion_time
            out = mode.update(self.motion_time, m)
            self.mode_output = out
            if out.failure is not None:
                # The mode cannot go on safely (lost marker, capture not confirmed, ...).
                self.protective_stop(m.time, out.failure)
                command = self._stopping_command() if self.stopping is not None else None
                if command is not None:
                    return command
                self.last_target = None
                return Command(m.q.copy(), _zeros_as(m.q), enable=False)
            setpoint = out.setpoint
            self.last_setpoint = setpoint
            if mode.moving and out.finished:
                self._event(m.time, "motion", f"{mode.name} finished")
                self.motions_finished = self.motions_started
                self._set_mode(HoldMode(setpoint.q.copy()))
            self.last_target = setpoint.q.copy()
            return built(Command, {"q": setpoint.q.copy(), "dq": setpoint.dq * self.resume_rate, "enable": True,
                                   "end_effector": out.end_effector})
        # Not enabled: targets follow the measurement so enabling never causes a jump.
        self.last_target = None
        self.last_setpoint = None
        return built(Command, {"q": m.q.copy(), "dq": _zeros_as(m.q), "enable": self._state is _ENABLING,
                               "end_effector": None})

    def _stopping_command(self) -> Command | None:
        """The planner's stop this cycle: its setpoint with the drives enabled; None once the
        rest setpoint has been sent for a cycle, and the drives are asked to quick stop (at
        rest their ramp is over at once: power off and brakes, category 1)."""
        stop = self.stopping
        stopped = self.state is MachineState.STOPPED
        # this cycle's target is one period on from the setpoint the drives had (no repeated target)
        elapsed = self.motion_time - self._stopping_since + self.period
        if elapsed > stop.duration + self.period + 1e-9:
            self.stopping = None
            if stopped:
                self.drive_request = DriveRequest.QUICK_STOP
                self.stop_monitor.quick_stop_requested(self.last_measurement.time if self.last_measurement else 0.0)
                self._event(self.last_measurement.time if self.last_measurement else 0.0, "stop",
                            "at rest: drives quick stop, brakes on")
            return None
        setpoint = stop.sample(min(elapsed, stop.duration))
        self.last_target = setpoint.q.copy()
        self.last_setpoint = setpoint
        return Command(setpoint.q.copy(), setpoint.dq.copy(), enable=True)

    def _set_mode(self, mode: Mode | None) -> None:
        self.mode = mode
        self.mode_output = None

    def mode_progress(self) -> float:
        return self.mode_output.progress if self.mode_output is not None else 0.0

    @property
    def stop_finished(self) -> bool:
        """No stop running: not stopped, or stopped with the planner done and no drive in operation."""
        m = self.last_measurement
        powered_off = self.stop_policy is not None and self.stop_policy.category == 0
        if self.state is not MachineState.STOPPED:
            return True
        if self.stopping is not None or m is None:
            return False
        powered = m.joints_powered if m.joints_powered is not None else m.joints_enabled
        return powered_off or not np.any(powered)

    def protective_stop(self, t: float, finding: Finding) -> None:
        if self.state is MachineState.STOPPED:       # a stop while stopping: the stronger one wins
            self._escalate(t, finding)
            return
        policy = stop_policy(finding.code)
        was_enabled = self.state is MachineState.ENABLED
        self.state = MachineState.STOPPED
        self._set_mode(None)
        self.stop_reason = finding
        self.stop_policy = policy
        self._event(t, "protective_stop", finding.message, finding)
        m = self.last_measurement
        self.stopping = None
        self.drive_request = DriveRequest.DISABLE if policy.category == 0 else DriveRequest.QUICK_STOP
        if m is None:
            return
        self.stop_monitor.start(m)
        if policy.rank == 0 and was_enabled and self.a_max is not None:
            q0, v0 = self._stop_start(m)
            self.stopping = StopTrajectory(q0, v0, self.a_max, self.period)
            self._stopping_since = self.motion_time
        else:
            self.stop_monitor.quick_stop_requested(t)

    def _stop_start(self, m: Measurement) -> tuple[np.ndarray, np.ndarray]:
        """Where the planner's stop starts: the setpoint the drives follow (no step in position
        or speed) while the measurement is within the following-error window of it; else (a
        following-error stop: the joint was held or pushed) the measured position and speed."""
        sp = self.last_setpoint
        window = np.broadcast_to(self.supervisor.limits.following_error, m.q.shape)
        if sp is not None and np.all(np.abs(sp.q - m.q) <= window):
            return sp.q.copy(), sp.dq.copy()
        v_max = self.supervisor.limits.v_max
        return m.q.copy(), np.clip(m.dq, -v_max, v_max)

    def _escalate(self, t: float, finding: Finding) -> None:
        """While stopped: a finding whose policy is stronger than the running stop's takes over
        (the planner's stop gives way to the drives' quick stop, anything to power off)."""
        policy = stop_policy(finding.code)
        if self.stop_policy is not None and policy.rank <= self.stop_policy.rank:
            return
        self.stop_policy = policy
        self.stopping = None
        self.drive_request = DriveRequest.DISABLE if policy.category == 0 else DriveRequest.QUICK_STOP
        self.stop_monitor.quick_stop_requested(t)
        if policy.category == 0:
            self.stop_monitor.end()
        self._event(t, "stop_escalated", f"{finding.message} ({policy.decelerator.value}, category {policy.category})",
                    finding)

    def drain_events(self) -> list[Event]:
        events, self.events = self.events, []
        return events

    def _event(self, t: float, kind: str, message: str, finding: Finding | None = None) -> None:
        self.events.append(Event(t, kind, message, finding))

    def _apply_pending(self, m: Measurement) -> None:
        # Nearly every cycle takes no request: one look at the queue's deque (empty() took its
        # lock, ~0.4 us) instead of get_nowait's raised and caught Empty (~2 us, issue 35). A
        # request put after the look is taken next cycle, as one put after get_nowait's look
        # always was.
        while self._pending.queue:      # the queue's deque: its length is read whole under the GIL
            try:
                pending = self._pending.get_nowait()
            except queue.Empty:
                break
            if not pending.future.set_running_or_notify_cancel():
                continue
            result, error = None, None
            try:
                result = pending.apply(m.time, m)
            except CommandRefused as exc:
                error = exc
            except PlanningError as exc:
                error = CommandRefused(str(exc), ErrorCode.PLANNING_REFUSED)
            except Exception as exc:  # a bug in a command must not kill the cycle
                error = CommandRefused(f"internal error: {exc!r}", ErrorCode.INTERNAL)
            self._answers.append((pending.future, result, error))
        if not self.defer_answers:
            self.answer_commands()

    def answer_commands(self) -> None:
        """Hand the commands this cycle took their answers (the daemon: after its snapshot)."""
        if not self._answers:       # twice a cycle, nearly always nothing to answer
            return
        answers, self._answers = self._answers, []
        for future, result, error in answers:
            if error is None:
                future.set_result(result)
            else:
                future.set_exception(error)

    # ---- commands (run inside the cycle via submit) ------------------------------------
    def cmd_enable(self, t: float, m: Measurement) -> str:
        if self.state is MachineState.STOPPED:
            raise CommandRefused(f"protective stop active ({self.stop_reason}); reset first", ErrorCode.PROTECTIVE_STOP)
        if self.state in (MachineState.ENABLING, MachineState.ENABLED):
            return self.state
        faulted = [n for n, f in zip(self.joint_names, m.joints_faulted) if f]
        if faulted:
            # Right after a reset the drives' fault reset takes a few cycles: refuse instead of
            # enabling into a "drive in fault" protective stop.
            raise CommandRefused(f"drive fault on {', '.join(faulted)}: reset first "
                                 "(right after a reset: try again in a moment)", ErrorCode.DRIVE_FAULT)
        self.state = MachineState.ENABLING
        self._enable_started = t
        self._event(t, "state", "enabling joints")
        return self.state

    def cmd_disable(self, t: float, m: Measurement) -> str:
        """Power off; a moving arm is first brought to rest by the planner (as a stop, without
        its reason: the state stays `enabled` until then, and no motion is taken meanwhile)."""
        if self.state is MachineState.STOPPED or self.stopping is not None:
            return self.state
        moving = self.mode is not None and self.mode.moving and self.last_setpoint is not None
        if self.state is MachineState.ENABLED and moving and self.a_max is not None:
            q0, v0 = self._stop_start(m)
            self.stopping = StopTrajectory(q0, v0, self.a_max, self.period)
            self._stopping_since = self.motion_time
            self._set_mode(None)
            self._event(t, "state", "disabling: stopping the motion first")
            return self.state
        self.state = MachineState.DISABLED
        self._set_mode(None)
        self._event(t, "state", "disabled, brakes on")
        return self.state

    def cmd_stop(self, t: float, m: Measurement) -> str:
        """Accepted in every state (anyone may stop the arm): stopping, it changes nothing."""
        self.protective_stop(t, Finding(FindingCode.OPERATOR_STOP, "stop commanded by the operator"))
        return self.state

    def cmd_reset(self, t: float, m: Measurement) -> str:
        if self.state is MachineState.STOPPED and not self.stop_finished:
            raise CommandRefused("the arm is still stopping; reset once it is at rest", ErrorCode.BUSY)
        if self.state is not MachineState.STOPPED:
            faulted = [n for n, f in zip(self.joint_names, m.joints_faulted) if f]
            if faulted and self.state is MachineState.DISABLED:
                # e.g. after a daemon restart: the drives faulted when the controller vanished
                self._event(t, "reset", f"fault reset of {', '.join(faulted)}")
            return self.state
        self.state = MachineState.DISABLED
        self._event(t, "reset", f"reset after: {self.stop_reason}")
        self.stop_reason = None
        self.stop_policy = None
        self.stop_monitor.end()
        return self.state

    def motion_start(self, t: float, m: Measurement) -> np.ndarray:
        """Where the next motion must start: the current target. Refuses if not ready."""
        if self.state is MachineState.STOPPED:
            raise CommandRefused(f"protective stop active ({self.stop_reason}); reset first", ErrorCode.PROTECTIVE_STOP)
        if self.state is not MachineState.ENABLED:
            raise CommandRefused(f"arm is {self.state}; enable it first", ErrorCode.NOT_ENABLED)
        if self.stopping is not None:
            raise CommandRefused("the arm is stopping to be disabled", ErrorCode.BUSY)
        if self.mode is not None and self.mode.moving and not (self.mode_output is not None and self.mode_output.finished):
            raise CommandRefused(f"{self.mode.name} still in progress; stop it or wait", ErrorCode.BUSY)
        return (self.last_target if self.last_target is not None else m.q).copy()

    def start_planned(self, t: float, m: Measurement, mode: Mode, planned_from: np.ndarray | None) -> dict:
        """Start a motion planned outside the cycle from `planned_from` (if given and still
        valid), or a reactive mode that plans as it goes (`planned_from` None)."""
        start = self.motion_start(t, m)
        if planned_from is not None and not np.allclose(start, planned_from, atol=1e-9, rtol=0):
            raise CommandRefused("the arm moved while the motion was being planned; send it again", ErrorCode.MOVED)
        mode.start = self.motion_time
        self._set_mode(mode)
        self.motions_started += 1
        self._event(t, "motion", f"{mode.name} started: {mode.description}")
        plan = getattr(mode, "plan", None)
        return {"mode": mode.name, "duration": plan.duration if plan is not None else None,
                "motion": self.motions_started}
