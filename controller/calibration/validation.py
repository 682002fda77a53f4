"""Validation on independent configurations: per-axis errors as in the papers' tables.

Laser-ranger paper Table 5: per axis x, y, z: RMS position, RMS orientation, max |position|,
max |orientation| (eq. 16). EKF paper Table 4: mean and extreme of the position error norm and
of |orientation error| about each axis.
Orientation errors are the rotation vector of R_true R_pred^T (base frame), small angles.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from spacearm.controller.calibration.residuals import rotvec_batch

Array = NDArray[np.float64]


@dataclass
class ValidationStats:
    pos: Array          # (N, 3) true - predicted position, m
    rot: Array          # (N, 3) rotation vector errors, rad

    @property
    def rms_pos(self) -> Array:
        return np.sqrt(np.mean(self.pos ** 2, axis=0))

    @property
    def rms_rot(self) -> Array:
        return np.sqrt(np.mean(self.rot ** 2, axis=0))

    @property
    def max_pos(self) -> Array:
        return np.abs(self.pos).max(axis=0)

    @property
    def max_rot(self) -> Array:
        return np.abs(self.rot).max(axis=0)

    @property
    def pos_norm(self) -> Array:
        return np.linalg.norm(self.pos, axis=1)

    def table5(self) -> dict[str, Array]:
        """Laser paper Table 5 columns (SI)."""
        return {"rms_pos": self.rms_pos, "rms_rot": self.rms_rot, "max_pos": self.max_pos,
                "max_rot": self.max_rot}

    def table4(self) -> dict[str, float]:
        """EKF paper Table 4 rows (SI): position norm and per-axis |orientation| mean/extreme."""
        out = {"pos_mean": float(self.pos_norm.mean()), "pos_max": float(self.pos_norm.max())}
        for k, ax in enumerate("xyz"):
            out[f"rot{ax}_mean"] = float(np.abs(self.rot[:, k]).mean())
            out[f"rot{ax}_max"] = float(np.abs(self.rot[:, k]).max())
        return out


def compare_poses(T_true: Array, T_pred: Array) -> ValidationStats:
    """Errors of predicted poses against true poses (N, 4, 4)."""
    pos = T_true[:, :3, 3] - T_pred[:, :3, 3]
    rot = rotvec_batch(T_true[:, :3, :3] @ np.swapaxes(T_pred[:, :3, :3], 1, 2))
    return ValidationStats(pos, rot)


def mean_stats(stats: list[ValidationStats]) -> dict[str, Array]:
    """Monte-Carlo mean of the Table 5 quantities."""
    keys = stats[0].table5().keys()
    return {k: np.mean([s.table5()[k] for s in stats], axis=0) for k in keys}
