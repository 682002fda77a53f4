"""Cartesian moves resolved into joint motion (ORU paper eqs. 2-4), planned up front.

The whole path is integrated when the move is commanded: at each cycle the joint rates
are q_dot = J^+ (v_d + k e), with e the pose error to the path (closed-loop inverse
kinematics, so integration drift cannot build up), and q(t + dt) = q(t) + q_dot dt.
The result is checked against joint position and velocity limits and the final pose
error before any motion starts; the control cycle only plays the joint samples back.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from spacearm.base.kinematics.pose_error import twist_error as pose_error
from spacearm.controller.planning.cartesian_path import CartesianPath
from spacearm.controller.planning.errors import PlanningError, PlanningFailure
from spacearm.controller.planning.joint_move import JointLimits, JointSetpoint

Forward = Callable[[np.ndarray], np.ndarray]     # q -> 4x4 tool pose
Jacobian = Callable[[np.ndarray], np.ndarray]    # q -> 6 x n geometric Jacobian


def damped_pinv(J: np.ndarray, damping: float) -> np.ndarray:
    """J^T (J J^T + lambda^2 I)^-1: bounded joint rates near singularities."""
    return J.T @ np.linalg.solve(J @ J.T + damping**2 * np.eye(J.shape[0]), np.eye(J.shape[0]))


@dataclass(frozen=True)
class SampledJointPath:
    period: float
    q: np.ndarray        # (k+1, n) joint positions at t = i * period
    dq: np.ndarray       # (k+1, n) joint velocities

    @property
    def duration(self) -> float:
        return (len(self.q) - 1) * self.period

    def sample(self, t: float) -> JointSetpoint:
        i = int(np.clip(round(t / self.period), 0, len(self.q) - 1))
        return JointSetpoint(self.q[i], self.dq[i], np.zeros_like(self.q[i]))


def resolve_cartesian_path(path: CartesianPath, q_start: np.ndarray, forward: Forward,
                           jacobian: Jacobian, limits: JointLimits, period: float,
                           gain: float = 5.0, damping: float = 1e-3,
                           tolerance: tuple[float, float] = (1e-4, 1e-3)) -> SampledJointPath:
    """Integrate eqs. 3-4 along `path`; raise PlanningError if the arm cannot follow it.

    tolerance: allowed final (position m, orientation rad) error against the goal pose.
    """
    steps = max(1, int(np.ceil(path.duration / period)))
    n = len(q_start)
    qs = np.empty((steps + 1, n))
    dqs = np.zeros((steps + 1, n))
    q = np.array(q_start, dtype=float)
    qs[0] = q
    for k in range(1, steps + 1):
        t = min(k * period, path.duration)
        sample = path.sample(t)
        twist = np.concatenate([sample.linear_velocity, sample.angular_velocity])
        dq = damped_pinv(jacobian(q), damping) @ (twist + gain * pose_error(sample.pose, forward(q)))
        q = q + dq * period
        qs[k], dqs[k] = q, dq
        _check_limits(k * period, q, dq, limits)
    # Settle the last few micro-radians with the goal held, still inside the limits.
    for _ in range(20):
        error = pose_error(path.goal, forward(q))
        if np.linalg.norm(error[:3]) <= tolerance[0] / 10 and np.linalg.norm(error[3:]) <= tolerance[1] / 10:
            break
        q = q + damped_pinv(jacobian(q), damping) @ error
    error = pose_error(path.goal, forward(q))
    if np.linalg.norm(error[:3]) > tolerance[0] or np.linalg.norm(error[3:]) > tolerance[1]:
        raise PlanningError(
            f"Cartesian goal not reached along the straight path: remaining error "
            f"{np.linalg.norm(error[:3]) * 1e3:.2f} mm / {np.degrees(np.linalg.norm(error[3:])):.3f} deg "
            "(unreachable or through a singularity)",
            PlanningFailure.REACHABILITY)
    _check_limits(path.duration, q, np.zeros(n), limits)
    qs[-1] = q
    dqs[-1] = 0.0
    return SampledJointPath(period, qs, dqs)


def _check_limits(t: float, q: np.ndarray, dq: np.ndarray, limits: JointLimits) -> None:
    outside = np.flatnonzero((q < limits.q_min) | (q > limits.q_max))
    if outside.size:
        i = int(outside[0])
        raise PlanningError(f"joint {i + 1} would leave its limits at t = {t:.2f} s "
                            f"({q[i]:.4f} rad outside [{limits.q_min[i]:.4f}, {limits.q_max[i]:.4f}])",
                            PlanningFailure.JOINT_LIMITS)
    fast = np.flatnonzero(np.abs(dq) > limits.v_max * 1.05)
    if fast.size:
        i = int(fast[0])
        raise PlanningError(f"joint {i + 1} would need {abs(dq[i]):.4f} rad/s at t = {t:.2f} s, "
                            f"above its {limits.v_max[i]:.4f} rad/s limit (near a singularity?)",
                            PlanningFailure.JOINT_LIMITS)
