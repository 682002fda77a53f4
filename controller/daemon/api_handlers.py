"""Console commands: argument validation, control-lease checks, and dispatch to the cycle.

Arguments are validated here, in the API thread (types, counts, ranges, units are SI);
whether the command makes sense *now* (state, reachability) is decided inside the cycle
by ControllerCore. `stop` needs no lease: anyone watching may stop the arm.
"""
from __future__ import annotations

import math
import threading
import time
from concurrent.futures import TimeoutError as FutureTimeout
from typing import Any, Callable, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from spacearm.base.config.loader import RANGE_ERRORS, describe_range, field_for_location, format_location
from spacearm.controller.daemon.api_errors import ErrorCode
from spacearm.controller.daemon.command_api import ApiError, Session
from spacearm.controller.daemon.core import CommandRefused, ControllerCore
from spacearm.controller.daemon.leases import ControlLease, LeaseError
from spacearm.controller.modes import PlannedMode
from spacearm.controller.daemon.watchdog import KeepAliveMode
from spacearm.controller.planning.errors import PlanningError


# What the API answers while the drives are brought up (before the first cycle): anyone may stop.
BRING_UP_COMMANDS = frozenset({"ping", "status", "stop", "control.take", "control.release"})


class Args(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)
    lease: str | None = None


class NoArgs(Args):
    pass


class TakeArgs(Args):
    holder: str = Field(default="console", min_length=1, max_length=128)


class JogArgs(Args):
    joint: int = Field(ge=1, le=12, description="joint number, 1-based")
    delta: float = Field(ge=-math.pi / 2, le=math.pi / 2, description="rad")
    speed: float = Field(default=1.0, gt=0.0, le=1.0, description="fraction of the joint limits")


class MoveJointsArgs(Args):
    q: list[float] | None = Field(default=None, min_length=1, max_length=12, description="rad")
    posture: str | None = Field(default=None, min_length=1, max_length=64,
                                description="a named posture of the arm file ([postures], home)")
    speed: float = Field(default=1.0, gt=0.0, le=1.0)


class MovePoseArgs(Args):
    xyz: list[float] = Field(min_length=3, max_length=3, description="m")
    rpy: list[float] = Field(min_length=3, max_length=3, description="rad, R = Rz(yaw) Ry(pitch) Rx(roll)")
    frame: Literal["base", "tool"] = "base"
    speed: float = Field(default=1.0, gt=0.0, le=1.0)


class ApproachArgs(Args):
    target: str = Field(min_length=1, max_length=64, description="store name of the scene file")
    dz: float = Field(default=0.10, gt=0.0, le=0.5, description="m, stand-off of the pre-contact pose")
    holding: str | None = Field(default=None, min_length=1, max_length=64, description="ORU held by the end effector")


class RecordArgs(Args):
    path: str | None = Field(default=None, max_length=4096)


def _parse(model: type[Args], args: dict[str, Any]) -> Args:
    try:
        return model.model_validate(args)
    except ValidationError as exc:
        item = exc.errors()[0]
        message = item["msg"]
        if item["type"] in RANGE_ERRORS:   # the operator's words, not pydantic's ("Input should be ...")
            field = field_for_location(model, item["loc"])
            allowed = describe_range(field) if field is not None else None
            if allowed:
                message = f"{item.get('input')!r} is out of range: {allowed}"
        raise ApiError(f"{format_location(item['loc'])}: {message}", ErrorCode.BAD_ARGUMENT) from None


class CommandHandlers:
    """Maps command names to validated calls; the daemon passes `handle` to the server."""

    def __init__(self, core: ControllerCore, lease: ControlLease, planner: Any,
                 status: Callable[[], dict], recorder_control: Any, dof: int,
                 cycle_timeout: float = 2.0):
        self.core = core
        self.lease = lease
        self.planner = planner
        self.status = status
        self.recorder_control = recorder_control
        self.dof = dof
        self.cycle_timeout = cycle_timeout
        self.postures: dict[str, list[float]] = {}   # named postures (the daemon fills them from the arm file)
        self._local = threading.local()   # the session of the request this API thread serves
        self.table: dict[str, tuple[type[Args], bool, Callable[[Args], Any]]] = {
            # name: (argument model, needs control lease, action)
            "ping": (NoArgs, False, lambda a: "pong"),
            "status": (NoArgs, False, lambda a: self.status()),
            "control.take": (TakeArgs, False, self._take),
            "control.release": (NoArgs, True, lambda a: self.lease.release(a.lease) or "released"),
            "stop": (NoArgs, False, lambda a: self._stop()),
            "enable": (NoArgs, True, lambda a: self._in_cycle(self.core.cmd_enable)),
            "disable": (NoArgs, True, lambda a: self._in_cycle(self.core.cmd_disable)),
            "reset": (NoArgs, True, lambda a: self._in_cycle(self.core.cmd_reset)),
            "jog": (JogArgs, True, self._jog),
            "move_joints": (MoveJointsArgs, True, self._move_joints),
            "move_pose": (MovePoseArgs, True, self._move_pose),
            "approach": (ApproachArgs, True, self._approach),
            "record.start": (RecordArgs, True, lambda a: self.recorder_control.start(a.path)),
            "record.stop": (NoArgs, True, lambda a: self.recorder_control.stop()),
        }

    def handle(self, session: Session, cmd: str, args: dict[str, Any]) -> Any:
        entry = self.table.get(cmd)
        if entry is None:
            raise ApiError(f"unknown command {cmd!r}; known: {', '.join(sorted(self.table))}", ErrorCode.UNKNOWN_COMMAND)
        if session is not None:
            session.last_seen = time.monotonic()   # keep-alive for the command watchdog
        if self.core.last_measurement is None and cmd not in BRING_UP_COMMANDS:
            raise ApiError("the daemon is still bringing the drives up: only stop, status and ping until "
                           "status shows a state", ErrorCode.BUSY)
        model, needs_lease, action = entry
        parsed = _parse(model, args)
        self._local.session = session
        try:
            if needs_lease:
                self.lease.require(parsed.lease)
            return action(parsed)
        except (LeaseError, CommandRefused) as exc:
            raise ApiError(str(exc), exc.code) from None

    def _in_cycle(self, apply: Callable) -> Any:
        try:
            return self.core.submit(apply, timeout=self.cycle_timeout)
        except FutureTimeout:
            raise ApiError("the control cycle did not take the command in time", ErrorCode.CYCLE_TIMEOUT) from None

    def _stop(self) -> str:
        if self.core.last_measurement is None:     # bring-up: no cycle yet to wait for
            self.core.queue(self.core.cmd_stop)
            return "booting, stopped from its first cycle"
        return self._in_cycle(self.core.cmd_stop)

    def _take(self, a: TakeArgs) -> dict:
        return {"lease": self.lease.take(a.holder, a.lease), "holder": self.lease.holder}

    def _start_motion(self, name: str, description: str, plan_from: Callable[[np.ndarray], Any],
                      keepalive: bool = False) -> Any:
        """Plan in this (API) thread from the cycle's current target, then start in the cycle."""
        start = self._in_cycle(self.core.motion_start)
        try:
            plan = plan_from(start)
        except PlanningError as exc:
            raise ApiError(str(exc), ErrorCode.PLANNING_REFUSED) from None
        session = getattr(self._local, "session", None)
        if keepalive and session is not None:
            mode = KeepAliveMode(name, plan, 0.0, description, session=session)
        else:
            mode = PlannedMode(name, plan, 0.0, description)
        return self._in_cycle(lambda t, m: self.core.start_planned(t, m, mode, start))

    def _approach(self, a: ApproachArgs) -> Any:
        """Closed-loop approach (controller/daemon/approach_mode.py); needs a camera."""
        factory = (getattr(self, "mode_factories", None) or {}).get("approach")
        if factory is None:
            raise ApiError("no camera attached to the daemon (start it with --camera): approach unavailable",
                           ErrorCode.UNAVAILABLE)
        if not math.isfinite(a.dz):
            raise ApiError("dz: must be finite", ErrorCode.BAD_ARGUMENT)
        try:
            mode = factory(a.target, a.dz, a.holding)
        except (KeyError, ValueError) as exc:
            raise ApiError(str(exc).strip("'\""), ErrorCode.BAD_ARGUMENT) from None
        return self._in_cycle(lambda t, m: self.core.start_planned(t, m, mode, None))

    def _jog(self, a: JogArgs) -> Any:
        if a.joint > self.dof:
            raise ApiError(f"joint: {a.joint} is not a joint of this {self.dof}-joint arm", ErrorCode.BAD_ARGUMENT)
        return self._start_motion("jog", f"joint {a.joint} by {a.delta:+.4f} rad",
                                  lambda q0: self.planner.jog(q0, a.joint - 1, a.delta, a.speed),
                                  keepalive=True)

    def _move_joints(self, a: MoveJointsArgs) -> Any:
        if (a.q is None) == (a.posture is None):
            raise ApiError("give either q (joint values) or posture (a name)", ErrorCode.BAD_ARGUMENT)
        if a.posture is not None:
            if a.posture not in self.postures:
                raise ApiError(f"posture: unknown posture {a.posture!r}; this arm has "
                               f"{', '.join(sorted(self.postures)) or 'none'}", ErrorCode.BAD_ARGUMENT)
            a = a.model_copy(update={"q": list(self.postures[a.posture]), "posture": None})
        assert a.q is not None
        if len(a.q) != self.dof:
            raise ApiError(f"q: expected {self.dof} joint values, got {len(a.q)}", ErrorCode.BAD_ARGUMENT)
        goal = np.array(a.q)
        if not np.all(np.isfinite(goal)):
            raise ApiError("q: values must be finite", ErrorCode.BAD_ARGUMENT)
        return self._start_motion("move_joints", "to " + ", ".join(f"{v:.4f}" for v in goal) + " rad",
                                  lambda q0: self.planner.joint_move(q0, goal, a.speed))

    def _move_pose(self, a: MovePoseArgs) -> Any:
        if not all(math.isfinite(v) for v in (*a.xyz, *a.rpy)):
            raise ApiError("xyz/rpy: values must be finite", ErrorCode.BAD_ARGUMENT)
        return self._start_motion(
            "move_pose", f"{a.frame} frame xyz {a.xyz} m rpy {a.rpy} rad",
            lambda q0: self.planner.pose_move(q0, np.array(a.xyz), np.array(a.rpy), a.frame, a.speed))
