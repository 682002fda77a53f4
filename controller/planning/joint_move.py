"""Point-to-point joint moves: jerk-limited and time-synchronised, planned once with Ruckig.

The whole trajectory is computed when the move is commanded, so the control cycle only
samples it (no solver call inside the cycle) and its duration is known up front.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from ruckig import InputParameter, Result, Ruckig, Synchronization, Trajectory

from spacearm.controller.planning.errors import PlanningError, PlanningFailure


@dataclass(frozen=True)
class JointLimits:
    """Per-joint limits, SI units (rad, rad/s, rad/s^2, rad/s^3)."""
    q_min: np.ndarray
    q_max: np.ndarray
    v_max: np.ndarray
    a_max: np.ndarray
    j_max: np.ndarray

    @property
    def dof(self) -> int:
        return len(self.q_min)


@dataclass(frozen=True)
class JointSetpoint:
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray


class JointMove:
    """A planned move; `sample(t)` gives the setpoint t seconds after its start."""

    def __init__(self, trajectory: Trajectory, goal: np.ndarray):
        self._trajectory = trajectory
        self.goal = goal
        self.duration = float(trajectory.duration)

    @classmethod
    def plan(cls, q_start: np.ndarray, q_goal: np.ndarray, limits: JointLimits,
             dq_start: np.ndarray | None = None, ddq_start: np.ndarray | None = None,
             speed_scale: float = 1.0) -> "JointMove":
        q_start = np.asarray(q_start, dtype=float)
        q_goal = np.asarray(q_goal, dtype=float)
        n = limits.dof
        if q_start.shape != (n,) or q_goal.shape != (n,):
            raise PlanningError(f"expected {n} joint values, got start {q_start.shape}, goal {q_goal.shape}")
        if not np.all(np.isfinite(q_goal)):
            raise PlanningError("goal contains a non-finite value")
        if not 0.0 < speed_scale <= 1.0:
            raise PlanningError(f"speed scale must be in (0, 1], got {speed_scale}")
        outside = np.flatnonzero((q_goal < limits.q_min) | (q_goal > limits.q_max))
        if outside.size:
            i = int(outside[0])
            raise PlanningError(
                f"joint {i + 1} goal {q_goal[i]:.4f} rad is outside its limits "
                f"[{limits.q_min[i]:.4f}, {limits.q_max[i]:.4f}] rad", PlanningFailure.JOINT_LIMITS)
        zeros = np.zeros(n)
        params = InputParameter(n)
        params.current_position = q_start.tolist()
        params.current_velocity = (zeros if dq_start is None else np.asarray(dq_start, float)).tolist()
        params.current_acceleration = (zeros if ddq_start is None else np.asarray(ddq_start, float)).tolist()
        params.target_position = q_goal.tolist()
        params.target_velocity = zeros.tolist()
        params.target_acceleration = zeros.tolist()
        params.max_velocity = (limits.v_max * speed_scale).tolist()
        params.max_acceleration = (limits.a_max * speed_scale).tolist()
        params.max_jerk = (limits.j_max * speed_scale).tolist()
        # Time synchronisation: every joint starts and ends together (straight-ish joint path).
        params.synchronization = Synchronization.Time
        trajectory = Trajectory(n)
        result = Ruckig(n).calculate(params, trajectory)
        if result not in (Result.Working, Result.Finished):
            raise PlanningError(f"Ruckig could not plan the move: {result.name}", PlanningFailure.PLANNER)
        return cls(trajectory, q_goal.copy())

    def sample(self, t: float) -> JointSetpoint:
        t = min(max(t, 0.0), self.duration)
        q, dq, ddq = self._trajectory.at_time(t)
        return JointSetpoint(np.asarray(q), np.asarray(dq), np.asarray(ddq))

    def finished(self, t: float) -> bool:
        return t >= self.duration
