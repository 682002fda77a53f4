"""Plans the daemon's motions from the arm's nominal model: jog, joint move, Cartesian move.

Runs in the command API's threads, never in the control cycle; each call has its own
kinematics scratch data, so concurrent consoles cannot corrupt each other's plans.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from spacearm.base.config.arm import CartesianLimits as CartesianLimitsConfig
from spacearm.base.kinematics.forward import fk
from spacearm.base.kinematics.jacobian import jacobian
from spacearm.base.kinematics.model import KinematicData, KinematicModel
from spacearm.base.spatial import rpy_to_matrix
from spacearm.controller.planning.cartesian_path import CartesianLimits, CartesianPath
from spacearm.controller.planning.errors import PlanningError, PlanningFailure
from spacearm.controller.planning.joint_move import JointLimits, JointMove
from spacearm.controller.planning.resolved_rate import SampledJointPath, resolve_cartesian_path


def joint_limits_of(model: KinematicModel) -> JointLimits:
    return JointLimits(np.array(model.q_min), np.array(model.q_max), np.array(model.v_max),
                       np.array(model.a_max), np.array(model.j_max))


class MotionPlanner:
    def __init__(self, model: KinematicModel, period: float,
                 cartesian: CartesianLimitsConfig = CartesianLimitsConfig()):
        self.model = model
        self.period = period
        self.limits = joint_limits_of(model)
        self.cartesian = CartesianLimits(cartesian.linear_velocity, cartesian.linear_acceleration,
                                         cartesian.angular_velocity, cartesian.angular_acceleration)

    def joint_move(self, q0: np.ndarray, goal: np.ndarray, speed: float = 1.0) -> JointMove:
        return JointMove.plan(q0, goal, self.limits, speed_scale=speed)

    def jog(self, q0: np.ndarray, joint: int, delta: float, speed: float = 1.0) -> JointMove:
        if not 0 <= joint < self.model.nq:
            raise PlanningError(f"joint {joint + 1} does not exist (arm has {self.model.nq})")
        goal = np.array(q0, dtype=float)
        goal[joint] += delta
        return self.joint_move(q0, goal, speed)

    def tool_pose(self, q: np.ndarray) -> np.ndarray:
        return fk(self.model, KinematicData(self.model), q).copy()

    def pose_move(self, q0: np.ndarray, xyz: np.ndarray, rpy: np.ndarray, frame: str = "base",
                  speed: float = 1.0) -> SampledJointPath:
        """Straight-line tool move to a pose given in the base frame or relative to the tool."""
        target = np.eye(4)
        target[:3, :3] = rpy_to_matrix(rpy)
        target[:3, 3] = xyz
        start = self.tool_pose(q0)
        if frame == "tool":
            target = start @ target
        elif frame != "base":
            raise PlanningError(f"frame must be 'base' or 'tool', got {frame!r}")
        if np.linalg.norm(target[:3, 3] - self.model.base[:3, 3]) > self.model.reach:
            raise PlanningError(f"target {np.round(target[:3, 3], 4).tolist()} m is beyond the "
                                f"arm's reach ({self.model.reach:.3f} m)", PlanningFailure.REACHABILITY)
        limits = self.cartesian
        if speed != 1.0:
            limits = replace(limits, linear_velocity=limits.linear_velocity * speed,
                             angular_velocity=limits.angular_velocity * speed,
                             linear_acceleration=limits.linear_acceleration * speed,
                             angular_acceleration=limits.angular_acceleration * speed)
        path = CartesianPath.within_limits(start, target, limits, min_duration=self.period)
        data = KinematicData(self.model)
        return resolve_cartesian_path(path, np.asarray(q0, float), lambda q: fk(self.model, data, q),
                                      lambda q: jacobian(self.model, data, q), self.limits, self.period)

