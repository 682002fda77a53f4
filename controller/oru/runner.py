"""The ORU changeout task runner: itself a daemon Mode that drives the Table 1 steps.

State: running -> (paused <-> running) -> done | aborted | failed. The runner keeps its own
clock, which stops while paused, so a paused free motion or contact resumes where it was; a
paused runner holds the last joint target. Any step failure (force limit, capture not
confirmed, end-effector fault or timeout, jammed insertion, planning refused) is reported in
the runner's output, and the daemon core makes a protective stop (quick stop, brakes) and
keeps the reason. The closed-loop approach's camera failures (vision_lost, camera_stopped,
frame_stale) are not stops: the runner holds `retry_hold` s and starts the approach again, up
to `approach_retries` times, then pauses with the code and message (`pause` in status);
resume starts the approach afresh. Abort ends the flow holding the current target.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from spacearm.controller.modes import ModeBase
from spacearm.controller.cycle import Finding, Measurement, ModeOutput, hold
from spacearm.controller.oru.flow import FlowContext, stage_steps
from spacearm.controller.oru.steps import ContactStep, Step


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
        self.pause_reason: Finding | None = None    # why the flow paused itself (vision retries used up)
        self._retries = 0                           # of the current approach step
        self._hold_until = 0.0                      # runner clock: hold still before a retry

    # ---- operator commands (run inside the cycle) ------------------------------------
    def pause(self) -> str:
        if self.state == "running":
            self.state = "paused"
        return self.state

    def resume(self) -> str:
        if self.state == "paused":
            self.state = "running"
            self.pause_reason = None
            self._retries = 0
        return self.state

    def abort(self) -> str:
        if self.state in ("running", "paused"):
            self.state = "aborted"
        return self.state

    # ---- Mode ------------------------------------------------------------------------
    def update(self, t: float, m: Measurement) -> ModeOutput:
        """One cycle of the flow on the runner's own clock (which stops while paused)."""
        out = self._advance(m)
        return ModeOutput(out.setpoint, out.end_effector, self._failure, self.state in ("done", "aborted"),
                          self.progress())

    def _advance(self, m: Measurement) -> ModeOutput:
        period = self.ctx.impedance.period
        if self.state != "running" or self._failure is not None:
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
        out = step.update(self.clock, m)
        self._step_progress = out.progress
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
        return out

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
