"""A straight-line tool move computed inside the cycle (the open-loop approach fallback).

The planned Cartesian move (MotionPlanner.pose_move) resolves the whole path up front, about
0.2 s of CPU; here the pose is interpolated (quintic time law, rotation about one axis) and
mapped to joints by two damped least-squares steps per cycle from the last command, ~0.2 ms.
"""
from __future__ import annotations

import numpy as np

from spacearm.controller.modes import ModeBase
from spacearm.controller.cycle import Measurement
from spacearm.base.kinematics.forward import fk
from spacearm.base.kinematics.jacobian import fk_jacobian
from spacearm.base.kinematics.model import KinematicData, KinematicModel
from spacearm.base.kinematics.pose_error import twist_error
from spacearm.base.spatial import matrix_to_rotvec, rotvec_to_matrix
from spacearm.controller.planning.quintic import quintic
from spacearm.controller.planning.joint_move import JointSetpoint

IK_DAMPING = 1.0e-3


class LinearToolMove(ModeBase):
    def __init__(self, model: KinematicModel, q_start: np.ndarray, target: np.ndarray, period: float,
                 linear_velocity: float, angular_velocity: float, name: str = "linear move"):
        self.name = self.description = name
        self.model = model
        self.data = KinematicData(model)
        self.period = period
        self.q_cmd = np.asarray(q_start, float).copy()
        self.X0 = fk(model, self.data, self.q_cmd).copy()
        self.target = np.asarray(target, float)
        self.dp = self.target[:3, 3] - self.X0[:3, 3]
        self.rotvec = matrix_to_rotvec(self.target[:3, :3] @ self.X0[:3, :3].T)
        # A quintic's peak speed is 1.875 x the mean: size the duration on it.
        self.duration = max(1.875 * float(np.linalg.norm(self.dp)) / linear_velocity,
                            1.875 * float(np.linalg.norm(self.rotvec)) / angular_velocity, 4 * period)
        self.elapsed = 0.0
        self._last_t: float | None = None

    def _next_setpoint(self, t: float, m: Measurement) -> JointSetpoint:
        # Advance by the caller's clock (one period per call when it runs at full rate), so a
        # runner that slows its clock to pause or resume slows this move along its path too.
        step = self.period if self._last_t is None else max(0.0, t - self._last_t)
        self._last_t = t
        self.elapsed = min(self.duration, self.elapsed + step)
        s = quintic(self.elapsed / self.duration)[0]
        Xd = np.eye(4)
        Xd[:3, :3] = rotvec_to_matrix(s * self.rotvec) @ self.X0[:3, :3]
        Xd[:3, 3] = self.X0[:3, 3] + s * self.dp
        q = self.q_cmd.copy()
        for _ in range(2):
            T, J = fk_jacobian(self.model, self.data, q)
            q = q + J.T @ np.linalg.solve(J @ J.T + IK_DAMPING ** 2 * np.eye(6), twist_error(Xd, T))
        dq = (q - self.q_cmd) / self.period      # per cycle of the daemon, whatever the clock did
        self.q_cmd = q
        return JointSetpoint(q.copy(), dq, np.zeros_like(q))

    def _finished(self, t: float) -> bool:
        return self.elapsed >= self.duration

    def _progress(self, t: float) -> float:
        return self.elapsed / self.duration
