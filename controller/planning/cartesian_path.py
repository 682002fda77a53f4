"""Cartesian straight-line paths with quintic timing (ORU paper, Section 4.1, eqs. 1-2).

Position moves along the straight line and orientation along the shortest rotation
(constant axis), both with the same quintic time law s(t), so the tool starts and stops
with zero velocity and acceleration. Joint rates come from the Jacobian elsewhere (eq. 3).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from spacearm.controller.planning.errors import PlanningError
from spacearm.controller.planning.quintic import QUINTIC_PEAK_ACCELERATION, QUINTIC_PEAK_VELOCITY, quintic


@dataclass(frozen=True)
class CartesianLimits:
    linear_velocity: float        # m/s
    linear_acceleration: float    # m/s^2
    angular_velocity: float       # rad/s
    angular_acceleration: float   # rad/s^2


@dataclass(frozen=True)
class CartesianSample:
    pose: np.ndarray             # 4x4 desired tool pose in the base frame
    linear_velocity: np.ndarray  # m/s, base frame
    angular_velocity: np.ndarray # rad/s, base frame


class CartesianPath:
    def __init__(self, start: np.ndarray, goal: np.ndarray, duration: float):
        if duration <= 0.0:
            raise PlanningError(f"path duration must be positive, got {duration}")
        self.start = np.array(start, dtype=float)
        self.goal = np.array(goal, dtype=float)
        self.duration = float(duration)
        self._dp = self.goal[:3, 3] - self.start[:3, 3]
        # Rotation from start to goal, expressed in the base frame: R_goal = R_delta R_start.
        self._rotvec = Rotation.from_matrix(self.goal[:3, :3] @ self.start[:3, :3].T).as_rotvec()

    @classmethod
    def within_limits(cls, start: np.ndarray, goal: np.ndarray, limits: CartesianLimits,
                      min_duration: float = 0.0) -> "CartesianPath":
        """The shortest quintic path that respects the velocity and acceleration limits."""
        distance = float(np.linalg.norm(goal[:3, 3] - start[:3, 3]))
        angle = float(np.linalg.norm(
            Rotation.from_matrix(goal[:3, :3] @ start[:3, :3].T).as_rotvec()))
        duration = max(
            min_duration,
            QUINTIC_PEAK_VELOCITY * distance / limits.linear_velocity,
            QUINTIC_PEAK_VELOCITY * angle / limits.angular_velocity,
            np.sqrt(QUINTIC_PEAK_ACCELERATION * distance / limits.linear_acceleration),
            np.sqrt(QUINTIC_PEAK_ACCELERATION * angle / limits.angular_acceleration),
        )
        if duration == 0.0:
            raise PlanningError("start and goal poses are identical")
        return cls(start, goal, duration)

    def sample(self, t: float) -> CartesianSample:
        s, ds, _ = quintic(t / self.duration)
        rate = ds / self.duration
        pose = np.eye(4)
        pose[:3, 3] = self.start[:3, 3] + s * self._dp
        pose[:3, :3] = Rotation.from_rotvec(s * self._rotvec).as_matrix() @ self.start[:3, :3]
        return CartesianSample(pose, rate * self._dp, rate * self._rotvec)
