"""Functional checkout of the arm: the main job until the ORU changeout flow replaces it.

enable -> joint move home->ready -> jog wrist roll and back -> Cartesian moves (tool
down 50 mm, turn 15 deg about the tool axis, back) -> joint move to home -> disable.
Each step goes through the same validated command path as a console command, and the
summary reports what the arm really did, measured from the recording.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from spacearm.controller.daemon.daemon import Daemon
from spacearm.base.kinematics import KinematicData, fk, matrix_to_rpy, position_error, rotation_error


@dataclass
class StepResult:
    name: str
    duration: float             # s of arm time
    max_tracking_error: float   # rad, max |q_cmd - q| over the step's cycles
    final_position_error: float | None = None   # m, tool pose from measured q vs the goal
    final_rotation_error: float | None = None   # rad (None: the step has no pose goal)


@dataclass
class CheckoutResult:
    steps: list[StepResult] = field(default_factory=list)
    recording: str | None = None
    cycles: int = 0
    stats: dict[str, Any] = field(default_factory=dict)
    wall_time: float = 0.0


@dataclass
class Step:
    name: str
    command: str
    args: dict[str, Any]
    goal: Callable[[Daemon], np.ndarray] | None = None  # tool pose expected at the end


def checkout_steps(daemon: Daemon) -> list[Step]:
    postures = daemon.arm.postures
    ready, home = postures["ready"], postures["home"]
    tool_at = lambda q: (lambda d: fk(d.model, KinematicData(d.model), np.array(q)))
    ready_tool = tool_at(ready)(daemon)
    last = daemon.model.nq
    return [
        Step("enable drives", "enable", {}),
        Step("joint move home -> ready", "move_joints", {"q": list(ready)}, tool_at(ready)),
        Step(f"jog joint {last} +10 deg", "jog", {"joint": last, "delta": math.radians(10)}),
        Step(f"jog joint {last} -10 deg", "jog", {"joint": last, "delta": -math.radians(10)}, tool_at(ready)),
        Step("Cartesian: tool 50 mm along its axis", "move_pose",
             {"xyz": [0.0, 0.0, 0.05], "rpy": [0.0, 0.0, 0.0], "frame": "tool"}),
        Step("Cartesian: turn 15 deg about the tool axis", "move_pose",
             {"xyz": [0.0, 0.0, 0.0], "rpy": [0.0, 0.0, math.radians(15)], "frame": "tool"}),
        Step("Cartesian: back to the ready pose", "move_pose",
             {"xyz": ready_tool[:3, 3].tolist(), "rpy": matrix_to_rpy(ready_tool[:3, :3]).tolist(),
              "frame": "base"}, tool_at(ready)),
        Step("joint move ready -> home", "move_joints", {"q": list(home)}, tool_at(home)),
        Step("disable drives, brakes on", "disable", {}),
    ]


class CheckoutFailed(Exception):
    pass


def run_checkout(daemon: Daemon, on_progress: Callable[[int, str, float], None]) -> CheckoutResult:
    """Run the steps on a started daemon whose cycle runs on another thread.

    on_progress(step_index, step_name, fraction) is called while steps run."""
    result = CheckoutResult()
    started = time.monotonic()
    lease = daemon.lease.take("checkout")
    steps = checkout_steps(daemon)
    for index, step in enumerate(steps):
        on_progress(index, step.name, 0.0)
        t_start = daemon.snapshot.tick.time
        errors: list[float] = []
        issued_at = daemon.snapshot.tick.cycle
        answer = daemon.handlers.handle(None, step.command, {**step.args, "lease": lease})
        motion = answer.get("motion") if isinstance(answer, dict) else None
        _wait(daemon, step, index, on_progress, errors, issued_at, motion)
        snapshot = daemon.snapshot
        outcome = StepResult(step.name, snapshot.tick.time - t_start, max(errors, default=0.0))
        if step.goal is not None:
            goal = step.goal(daemon)
            reached = fk(daemon.model, KinematicData(daemon.model), snapshot.measurement.q)
            outcome.final_position_error = position_error(goal, reached)
            outcome.final_rotation_error = rotation_error(goal, reached)
        result.steps.append(outcome)
        on_progress(index, step.name, 1.0)
    daemon.lease.release(lease)
    result.recording = str(daemon.recorder.path) if daemon.recorder else None
    result.cycles = daemon.stats.cycles
    result.stats = daemon.stats.summary().as_dict()
    result.wall_time = time.monotonic() - started
    return result


def _wait(daemon: Daemon, step: Step, index: int, on_progress, errors: list[float],
          issued_at: int, motion: int | None) -> None:
    """Follow the step cycle by cycle until it is done; fail on a protective stop.

    A motion is done when the daemon reports its number finished. Enable/disable take
    effect inside a cycle that publishes its snapshot afterwards, so snapshots up to one
    cycle after `issued_at` may predate them and are skipped."""
    last_cycle = -1
    while True:
        s = daemon.snapshot
        if s.tick.cycle <= issued_at + 1:
            time.sleep(0.001)
            continue
        if s.tick.cycle != last_cycle:
            last_cycle = s.tick.cycle
            if s.state == "enabled":
                errors.append(float(np.max(np.abs(s.command.q - s.measurement.q))))
        if s.state == "stopped":
            raise CheckoutFailed(f"{step.name}: protective stop: {s.stop_reason}")
        if step.command == "enable" and s.state == "enabled":
            return
        if step.command == "disable" and s.state == "disabled" and not np.any(s.measurement.joints_enabled):
            return
        if motion is not None:
            if s.motions_finished >= motion:
                return
            on_progress(index, step.name, s.progress)
        time.sleep(0.002)
