"""Gravity load on each joint at a posture, for the joint-elasticity terms of a calibration.

A real arm's joints (harmonic drives, belts, a torso's lead screw) give under the weight of the
links beyond them, so the joint's true angle is the encoder's plus k_j tau_j(q): a compliance
k_j (rad/(N m), or m/N on a prismatic joint) times the gravity torque (force) the links beyond
joint j exert about (along) its axis. This is the joint elasticity model of FIGAROH's geometric
calibration (`include_non_geometric`); the torques come from the arm file's inertials on the
nominal geometry, as there, so they are known per posture and only k_j is estimated.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from spacearm.base.kinematics import KinematicModel
from spacearm.base.kinematics.forward import frames
from spacearm.base.kinematics.model import KinematicData

Array = NDArray[np.float64]
GRAVITY = (0.0, 0.0, -9.81)      # m/s^2 in the arm's base frame (z up)


@dataclass(eq=False)
class JointLoad:
    """Gravity torques (N m) or forces (N) on each joint of `kin` from per-link masses and
    centres of mass (in each D-H link frame, as arm files store them)."""
    kin: KinematicModel
    masses: Array                       # (n,) kg
    coms: Array                         # (n, 3) m, link frames
    gravity: Array = field(default_factory=lambda: np.array(GRAVITY))
    _cache: dict = field(default_factory=dict, init=False, repr=False)

    @classmethod
    def from_config(cls, kin: KinematicModel, links: list) -> "JointLoad":
        """From an arm file's `[[links]]` (ArmConfig.links): one inertial per joint."""
        if len(links) != kin.nq:
            raise ValueError(f"joint elasticity needs one inertial per joint ({kin.nq}), the arm file has {len(links)}")
        return cls(kin, np.array([ln.mass for ln in links], float), np.array([ln.com for ln in links], float))

    def torques(self, Q: ArrayLike) -> Array:
        """(N, n) gravity torque about each revolute axis / force along each prismatic axis."""
        Q = np.atleast_2d(np.asarray(Q, float))
        key = (Q.shape, Q.tobytes())
        hit = self._cache.get(key)
        if hit is None:
            if len(self._cache) > 32:
                self._cache.clear()
            data = KinematicData(self.kin)
            hit = self._cache[key] = np.array([self._one(data, q) for q in Q])
        return hit

    def _one(self, data: KinematicData, q: Array) -> Array:
        kin = self.kin
        F = frames(kin, data, q)
        n = kin.nq
        # Link j's frame is F[j + 1]; joint j turns about z of F[j + 1] (modified D-H) or of F[j].
        axis_frame = F[1:n + 1] if kin.convention == "modified" else F[0:n]
        coms = np.einsum("jab,jb->ja", F[1:n + 1, :3, :3], self.coms) + F[1:n + 1, :3, 3]
        weights = self.masses[:, None] * self.gravity[None, :]
        prismatic = np.asarray(kin.prismatic, bool)
        out = np.empty(n)
        for i in range(n):
            z, o = axis_frame[i][:3, 2], axis_frame[i][:3, 3]
            if prismatic[i]:
                out[i] = z @ weights[i:].sum(axis=0)
            else:
                out[i] = z @ np.cross(coms[i:] - o, weights[i:]).sum(axis=0)
        return out
