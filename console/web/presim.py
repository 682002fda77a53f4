"""Presimulation (ORU paper Section 3.4): plan a command with the daemon's own planner and
checks before the operator sends it, and sample the plan for the ghost arm.

The planner is `MotionPlanner` built from the same arm file and period as the daemon, so a
command that passes here is the one the daemon will accept from the same start; the daemon
still validates and plans again when the command arrives (it decides, the page only shows).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from spacearm.base.config.loader import format_location
from spacearm.base.kinematics.model import KinematicData, KinematicModel
from spacearm.controller.planning.errors import PlanningError, PlanningFailure
from spacearm.controller.planning.motion_planner import MotionPlanner
from spacearm.console.web.state_feed import arm_frames

GHOST_SAMPLES = 60   # arm poses sent to the page along a planned motion


class Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)


class JogRequest(Strict):
    joint: int = Field(ge=1, le=12)
    delta: float = Field(ge=-math.pi / 2, le=math.pi / 2)
    speed: float = Field(default=1.0, gt=0.0, le=1.0)


class MoveJointsRequest(Strict):
    q: list[float] = Field(min_length=1, max_length=12)
    speed: float = Field(default=1.0, gt=0.0, le=1.0)


class MovePoseRequest(Strict):
    xyz: list[float] = Field(min_length=3, max_length=3)
    rpy: list[float] = Field(min_length=3, max_length=3)
    frame: str = Field(default="base", pattern="^(base|tool)$")
    speed: float = Field(default=1.0, gt=0.0, le=1.0)


REQUESTS: dict[str, type[Strict]] = {"jog": JogRequest, "move_joints": MoveJointsRequest,
                                     "move_pose": MovePoseRequest}


@dataclass
class Check:
    name: str
    ok: bool
    detail: str

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "ok": self.ok, "detail": self.detail}


@dataclass
class Presimulation:
    cmd: str
    args: dict[str, Any]
    accepted: bool
    checks: list[Check] = field(default_factory=list)
    duration: float = 0.0
    times: list[float] = field(default_factory=list)
    q: list[list[float]] = field(default_factory=list)        # joint path samples, rad
    frames: list[list[list[float]]] = field(default_factory=list)  # arm frames per sample
    reason: str | None = None

    def as_dict(self) -> dict[str, Any]:
        return {"type": "presim", "cmd": self.cmd, "args": self.args, "accepted": self.accepted,
                "reason": self.reason, "checks": [c.as_dict() for c in self.checks],
                "duration": self.duration, "times": self.times, "q": self.q, "frames": self.frames}


class Presimulator:
    def __init__(self, model: KinematicModel, period: float, planner: MotionPlanner | None = None):
        self.model = model
        self.planner = planner or MotionPlanner(model, period)

    def run(self, cmd: str, args: dict[str, Any], status: dict[str, Any] | None) -> Presimulation:
        result = Presimulation(cmd, dict(args), accepted=False)
        request_type = REQUESTS.get(cmd)
        if request_type is None:
            return self._refuse(result, "command", f"{cmd!r} cannot be presimulated "
                                f"(known: {', '.join(sorted(REQUESTS))})")
        try:
            request = request_type.model_validate(args)
        except ValidationError as exc:
            item = exc.errors()[0]
            return self._refuse(result, "arguments", f"{format_location(item['loc'])}: {item['msg']}")
        result.checks.append(Check("arguments", True, "types, counts and ranges valid"))
        if not status or not status.get("joints"):
            return self._refuse(result, "daemon state", "no state from the daemon yet")
        # The daemon plans from the cycle's current target (core.motion_start).
        q0 = np.array([j["q_cmd"] for j in status["joints"]], float)
        try:
            plan = self._plan(cmd, request, q0)
        except PlanningError as exc:
            return self._refuse(result, self._check_name(cmd, exc.kind), str(exc))
        result.checks.append(Check("joint limits", True, "every joint stays inside its limits along the path"))
        if cmd == "move_pose":
            result.checks.append(Check("reachability", True,
                                       "the straight tool path reaches the goal pose (resolved rate)"))
        result.checks.append(self._state_check(status))
        self._sample(result, plan)
        result.accepted = all(c.ok for c in result.checks)
        if not result.accepted:
            result.reason = next(c.detail for c in result.checks if not c.ok)
        return result

    def _plan(self, cmd: str, request: Strict, q0: np.ndarray) -> Any:
        if cmd == "jog":
            if request.joint > self.model.nq:
                raise PlanningError(f"joint {request.joint} is not a joint of this {self.model.nq}-joint arm")
            return self.planner.jog(q0, request.joint - 1, request.delta, request.speed)
        if cmd == "move_joints":
            if len(request.q) != self.model.nq:
                raise PlanningError(f"expected {self.model.nq} joint values, got {len(request.q)}")
            return self.planner.joint_move(q0, np.array(request.q), request.speed)
        return self.planner.pose_move(q0, np.array(request.xyz), np.array(request.rpy),
                                      request.frame, request.speed)

    @staticmethod
    def _check_name(cmd: str, failure: PlanningFailure) -> str:
        if failure is PlanningFailure.JOINT_LIMITS:
            return "joint limits"
        if failure is PlanningFailure.REACHABILITY or cmd == "move_pose":
            return "reachability"
        return "planning"

    @staticmethod
    def _state_check(status: dict[str, Any]) -> Check:
        state = status.get("state")
        if state == "enabled":
            if status.get("mode") not in (None, "hold") and status.get("progress", 1.0) < 1.0:
                return Check("arm state", False, f"{status['mode']} still in progress; stop it or wait")
            return Check("arm state", True, "enabled and idle")
        if state == "stopped":
            return Check("arm state", False, f"protective stop active ({status.get('stop_reason')}); reset first")
        return Check("arm state", False, f"arm is {state}; enable it first")

    def _sample(self, result: Presimulation, plan: Any) -> None:
        duration = float(plan.duration)
        times = np.linspace(0.0, duration, GHOST_SAMPLES) if duration > 0 else np.zeros(1)
        result.duration = duration
        result.times = np.round(times, 4).tolist()
        data = KinematicData(self.model)     # per call: pages presimulate concurrently
        for t in times:
            q = plan.sample(float(t)).q
            result.q.append(np.round(q, 6).tolist())
            result.frames.append(arm_frames(self.model, data, q))

    @staticmethod
    def _refuse(result: Presimulation, check: str, reason: str) -> Presimulation:
        result.checks.append(Check(check, False, reason))
        result.reason = reason
        result.accepted = False
        return result
