"""The ORU changeout task runner: itself a daemon Mode that drives the Table 1 steps.

State: running -> (pausing -> paused -> resuming -> running) -> done | aborted | failed. The
runner keeps its own clock, which stops while paused, so a paused free motion, approach or
contact resumes where it was; a paused runner holds the last joint target. Pause and resume
never step the clock's rate: it ramps 1 -> 0 and 0 -> 1 along a quintic (zero rate change and
zero curvature at both ends), over a time set from the joint limits and the path's speed
(PauseRamp), so the commanded velocity leaves and rejoins the path within the acceleration
limits and with bounded jerk, whichever step is running (path-time scaling, as an industrial
controller's speed override does). Any step failure (force limit, capture not
confirmed, end-effector fault or timeout, jammed insertion, planning refused, lost marker in
the approach) is reported in the runner's output, and the daemon core makes a protective stop
(quick stop, brakes) and keeps the reason. The closed-loop approach's camera failures
(vision_lost, camera_stopped, frame_stale) are not stops: the runner holds `retry_hold` s and starts the approach again, up to `approach_retries`
times, then pauses with the code and message (`pause` in status); resume starts the approach
afresh. Abort ends the flow holding the current target.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from spacearm.controller.modes import ModeBase
from spacearm.controller.cycle import Finding, Measurement, ModeOutput, hold
from spacearm.controller.oru.flow import FlowContext, stage_steps
from spacearm.controller.oru.steps import ContactStep, Step
from spacearm.controller.planning.joint_move import JointSetpoint


@dataclass
class StepRecord:
    stage: int
    number: int
    title: str
    algorithm: str
    started: float
    duration: float = 0.0
    peak_force: float = 0.0          # N, compensated contact force (contact steps)
    peak_lateral_force: float = 0.0
    peak_torque: float = 0.0
    peak_insert_force: float = 0.0
    notes: list[str] = field(default_factory=list)
    outcome: str = "running"         # running, then done | failed | retried | paused (how the attempt ended)
    q_end: list[float] | None = None  # measured joints when the step ended (handover to contact)
    sync_end: int | None = None       # SYNC of that measurement
    vision: dict | None = None       # the closed-loop approach's report() (frames, detection, latency)


def _quintic(x: float) -> float:
    """0 -> 1 with zero first and second derivative at both ends (peak slope 1.875)."""
    x = min(max(x, 0.0), 1.0)
    return x * x * x * (10.0 - 15.0 * x + 6.0 * x * x)


@dataclass
class PauseRamp:
    """The clock rate's ramp: rate(t) from `start` to `end` over `duration` s."""
    start: float
    end: float
    began: float        # runner-independent elapsed time (cycles x period) when it began
    duration: float

    def rate(self, elapsed: float) -> float:
        return self.start + (self.end - self.start) * _quintic((elapsed - self.began) / self.duration)

    def done(self, elapsed: float) -> bool:
        return elapsed - self.began >= self.duration


# The ramp's added acceleration is |path speed| x peak rate slope (1.875 / duration): with the
# duration RAMP_MARGIN x (speed / acceleration limit) it stays below half the limit.
RAMP_MARGIN = 4.0
RAMP_MIN = 0.2   # s


class OruTaskRunner(ModeBase):
    moving = True

    def __init__(self, ctx: FlowContext, stages: list[int] | None = None):
        self.ctx = ctx
        self.stage_names = [s.name for s in ctx.config.stages]
        chosen = stages if stages is not None else list(range(len(ctx.config.stages)))
        self.steps: list[Step] = []
        for i in chosen:
            self.steps += stage_steps(ctx, i, ctx.config.stages[i].store)
        self.contents = {s.name: s.holds for s in ctx.scene.stores}
        self.name = "oru"
        self.description = f"ORU changeout: {len(chosen)} stages, {len(self.steps)} subtasks"
        self.state = "running"
        self.index = 0
        self.clock = 0.0
        self.q_last = ctx.q_initial.copy()
        self.records: list[StepRecord] = []
        self._failure: Finding | None = None
        self._begun = False
        self._step_progress = 0.0
        self.rate = 1.0                              # the runner clock's rate (pause/resume ramps)
        self._ramp: PauseRamp | None = None
        self._elapsed = 0.0                          # cycles x period, never paused
        self._path_speed = np.zeros(len(ctx.q_initial))   # |dq/dclock| of the last running cycle
        self._last_dt = 0.0
        self.a_max = np.asarray(ctx.model.a_max, float)
        self.v_max = np.asarray(ctx.model.v_max, float)
        self.pause_reason: Finding | None = None    # why the flow paused itself (vision retries used up)
        self._retries = 0                           # of the current approach step
        self._hold_until = 0.0                      # runner clock: hold still before a retry

    # ---- operator commands (run inside the cycle) ------------------------------------
    def pause(self) -> str:
        """Slow the flow to rest along its path; 'paused' once the clock has stopped."""
        if self.state in ("running", "resuming"):
            self.state = "pausing"
            self._ramp = PauseRamp(self.rate, 0.0, self._elapsed, self._ramp_time())
        return self.state

    def resume(self) -> str:
        """Bring the flow from rest back up to speed along its path."""
        if self.state in ("paused", "pausing"):
            self.pause_reason = None
            self._retries = 0
            if self.rate >= 1.0:
                # paused by the flow itself (approach retries used up): its clock never slowed and
                # the arm is at rest; the approach starts afresh under its own acceleration limits
                self._ramp = None
                self.state = "running"
            else:
                self.state = "resuming"
                self._ramp = PauseRamp(self.rate, 1.0, self._elapsed, self._ramp_time())
        return self.state

    def _ramp_time(self) -> float:
        return float(max(RAMP_MIN, RAMP_MARGIN * np.max(self._path_speed / self.a_max)))

    def _advance_rate(self) -> None:
        """This cycle's clock rate; finishes a ramp (pausing -> paused, resuming -> running)."""
        ramp = self._ramp
        if ramp is None:
            return
        self.rate = ramp.rate(self._elapsed)
        if ramp.done(self._elapsed):
            self.rate = ramp.end
            self._ramp = None
            self.state = "paused" if ramp.end == 0.0 else "running"

    def abort(self) -> str:
        if self.state in ("running", "paused", "pausing", "resuming"):
            self.state = "aborted"
        return self.state

    # ---- Mode ------------------------------------------------------------------------
    def update(self, t: float, m: Measurement) -> ModeOutput:
        """One cycle of the flow on the runner's own clock (which stops while paused)."""
        self._elapsed += self.ctx.impedance.period
        self._advance_rate()
        out = self._advance(m)
        return ModeOutput(out.setpoint, out.end_effector, self._failure, self.state in ("done", "aborted"),
                          self.progress())

    def _advance(self, m: Measurement) -> ModeOutput:
        period = self.ctx.impedance.period * self.rate
        if self.state not in ("running", "pausing", "resuming") or self._failure is not None or period <= 0.0:
            self._last_dt = 0.0
            if self.state == "paused" and self._failure is None:
                return self._hold_contact(m)
            return ModeOutput(hold(self.q_last))
        if self.index >= len(self.steps):
            self.state = "done"
            return ModeOutput(hold(self.q_last))
        step = self.steps[self.index]
        if not self._begun:
            step.begin(self.q_last, self.clock)
            self.records.append(StepRecord(step.stage, step.number, step.title, step.algorithm, self.clock,
                                           notes=list(step.notes)))
            self.ctx.notes += [f"stage {step.stage + 1} subtask {step.number}: {n}" for n in step.notes]
            self._begun = True
        if self.clock < self._hold_until:
            self.clock += period
            return ModeOutput(hold(self.q_last))
        if isinstance(step, ContactStep):
            out = step.update(self.clock, m, self.rate)
        else:
            # the path runs at `rate` of its own speed while pausing or resuming: so does the
            # velocity sent with it (60B1h), or the drives push the joints ahead of their targets
            out = step.update(self.clock, m)
            sp = out.setpoint
            out = replace(out, setpoint=JointSetpoint(sp.q, sp.dq * self.rate, sp.ddq * self.rate ** 2))
        self._step_progress = out.progress
        if self._last_dt > 0.05 * self.ctx.impedance.period:   # path speed per clock second, for the next ramp
            # at most the velocity limits (a path is planned within them; a step change of
            # target, e.g. between steps, is no speed)
            self._path_speed = np.minimum(np.abs(out.setpoint.q - self.q_last) / self._last_dt, self.v_max)
        self.q_last = out.setpoint.q.copy()
        if out.failure is not None and out.failure.code in getattr(step, "retry_codes", ()):
            self._vision_failure(step, out.failure, m)
            return ModeOutput(hold(self.q_last))
        if out.failure is not None:
            self._failure = out.failure
            self.state = "failed"
            self._record(step, m, "failed")
            return out
        if out.finished:
            self._complete(step, m)
        self.clock += period
        self._last_dt = period        # the clock step between this setpoint and the next
        return out

    def _hold_contact(self, m: Measurement) -> ModeOutput:
        """Paused: hold the last target; in a contact step the impedance holds its reference
        instead (its admittance keeps regulating the force, the task does not progress), so the
        contact force and the commanded motion carry on smoothly through pause and resume."""
        step = self.steps[self.index] if self.index < len(self.steps) else None
        if not (isinstance(step, ContactStep) and self._begun):
            return ModeOutput(hold(self.q_last))
        out = step.update(self.clock, m, 0.0)
        if out.failure is not None:           # e.g. the force limit: the flow fails as when running
            self._failure = out.failure
            self.state = "failed"
            self._record(step, m, "failed")
            return out
        self.q_last = out.setpoint.q.copy()
        return ModeOutput(out.setpoint, out.end_effector)   # finishing waits for the resume

    def _vision_failure(self, step, failure: Finding, m: Measurement) -> None:
        """Hold, then retry the approach, or pause the flow once the retries are used up."""
        cfg = self.ctx.config.vision
        self._retries += 1
        retry = self._retries <= cfg.approach_retries
        self._record(step, m, "retried" if retry else "paused")
        step.reset()
        self._begun = False
        if retry:
            self._hold_until = self.clock + cfg.retry_hold
            self.ctx.notes.append(f"{failure.message}: holding {cfg.retry_hold:.1f} s, approach attempt "
                                  f"{self._retries + 1} of {cfg.approach_retries + 1}")
        else:
            self.state = "paused"
            self.pause_reason = Finding(failure.code, f"{failure.message} (after {cfg.approach_retries} "
                                        f"retries): flow paused, resume to try again or abort")
            self.ctx.notes.append(self.pause_reason.message)

    def _complete(self, step: Step, m: Measurement) -> None:
        self._retries = 0
        self._record(step, m)
        store = self.ctx.config.stages[step.stage].store
        if isinstance(step, ContactStep) and step.mode.task.tare_cycles > 0:
            self.ctx.ft_bias = step.mode.bias.copy()
        if step.number == 5:
            self.ctx.holding, self.contents[store] = self.contents.get(store), None
        elif step.number == 11:
            self.contents[store], self.ctx.holding = self.ctx.holding, None
        self.index += 1
        self._begun = False
        if self.index >= len(self.steps):
            self.state = "done"

    def _record(self, step: Step, m: Measurement, outcome: str = "done") -> None:
        rec = self.records[-1]
        rec.duration = self.clock - rec.started
        rec.outcome = outcome
        rec.q_end = [float(v) for v in m.q]
        rec.sync_end = int(m.sync_counter)
        report = getattr(getattr(step, "mode", None), "report", None)
        if callable(report):
            rec.vision = report()
        if isinstance(step, ContactStep):
            pk = step.mode.peaks
            rec.peak_force, rec.peak_torque = pk.force, pk.torque
            rec.peak_lateral_force, rec.peak_insert_force = pk.lateral_force, pk.insert_force

    def progress(self) -> float:
        if not self.steps or self.state == "done":
            return 1.0
        current = self._step_progress if self._begun and self.index < len(self.steps) else 0.0
        return float(np.clip((self.index + current) / len(self.steps), 0.0, 1.0))

    # ---- status ------------------------------------------------------------------------
    def current(self) -> Step | None:
        return self.steps[self.index] if self.index < len(self.steps) else None

    def status(self) -> dict:
        step = self.current()
        return {
            "state": self.state, "progress": self.progress(), "time": self.clock,
            "subtask_index": self.index, "subtasks": len(self.steps),
            "stage": None if step is None else step.stage + 1,
            "stage_name": None if step is None else self.stage_names[step.stage],
            "subtask": None if step is None else step.number,
            "title": None if step is None else step.title,
            "algorithm": None if step is None else step.algorithm,
            "holding": self.ctx.holding,
            "failure": None if self._failure is None else self._failure.message,
            "pause": None if self.pause_reason is None else {"code": str(self.pause_reason.code),
                                                             "message": self.pause_reason.message},
            "notes": list(self.ctx.notes),
            "records": [vars(r) | {"notes": list(r.notes)} for r in self.records],
        }
