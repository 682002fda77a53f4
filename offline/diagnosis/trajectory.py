"""Commanded joint trajectories: a CSV of `t, q_cmd_1..n` sampled into a daemon plan.

Between rows the position is interpolated linearly; the plan sends no velocity
feed-forward (dq = 0) so the drive's own CSP interpolation makes the velocity, and a replay
of the recorded q_cmd column reproduces the run exactly.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spacearm.controller.planning.joint_move import JointSetpoint


class TrajectoryError(ValueError):
    pass


@dataclass
class Trajectory:
    t: np.ndarray        # (N,) s from 0
    q: np.ndarray        # (N, n) rad

    @property
    def duration(self) -> float:
        return float(self.t[-1])

    def sample(self, t: float) -> JointSetpoint:
        q = np.array([np.interp(t, self.t, self.q[:, i]) for i in range(self.q.shape[1])])
        zeros = np.zeros_like(q)
        return JointSetpoint(q, zeros, zeros)

    def resampled(self, dt: float) -> np.ndarray:
        """Positions at dt steps from 0 to the end, (M, n)."""
        times = np.arange(0.0, self.duration + 0.5 * dt, dt)
        return np.column_stack([np.interp(times, self.t, self.q[:, i]) for i in range(self.q.shape[1])])


def load_trajectory(path: str | Path, n_joints: int | None = None) -> Trajectory:
    path = Path(path)
    try:
        with open(path) as handle:
            header = handle.readline().strip().split(",")
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    except (OSError, ValueError) as exc:
        raise TrajectoryError(f"{path}: cannot read trajectory CSV ({exc})") from None
    header = [h.strip() for h in header]
    if "t" not in header:
        raise TrajectoryError(f"{path}: no 't' column (need t, q_cmd_1..n)")
    cols = sorted((h for h in header if h.startswith("q_cmd_")), key=lambda h: int(h.split("_")[-1]))
    if not cols:
        raise TrajectoryError(f"{path}: no q_cmd_1..n columns")
    if n_joints is not None and len(cols) != n_joints:
        raise TrajectoryError(f"{path}: {len(cols)} q_cmd columns, the arm has {n_joints} joints")
    t = data[:, header.index("t")]
    if len(t) < 2 or np.any(np.diff(t) <= 0) or not np.all(np.isfinite(data)):
        raise TrajectoryError(f"{path}: t must increase and every value must be finite")
    return Trajectory(t - t[0], data[:, [header.index(c) for c in cols]])


def save_trajectory(path: str | Path, t: np.ndarray, q: np.ndarray) -> None:
    header = "t," + ",".join(f"q_cmd_{i + 1}" for i in range(q.shape[1]))
    np.savetxt(path, np.column_stack([t, q]), delimiter=",", header=header, comments="", fmt="%.9g")
