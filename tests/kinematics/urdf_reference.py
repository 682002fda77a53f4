"""Pinocchio as the independent reference for imported arms (FK, gravity, mass matrix)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin

REPO = Path(__file__).resolve().parents[2]
URDFS = {   # name: (URDF, base link, tip link)
    "ur10": (REPO / "configs/urdf/ur10/ur10_robot.urdf", "base_link", "tool0"),
    "panda": (REPO / "configs/urdf/panda/panda.urdf", "panda_link0", "panda_hand_tcp"),
    "tiago": (REPO / "configs/urdf/tiago/tiago_no_hand.urdf", "base_link", "arm_tool_link"),
}


class PinocchioChain:
    """The URDF loaded by Pinocchio, every joint off the chain locked at 0 (fixed base)."""

    def __init__(self, urdf: Path, base: str, tip: str, joint_names: list[str]) -> None:
        full = pin.buildModelFromUrdf(str(urdf))
        lock = [full.getJointId(n) for n in full.names[1:] if n not in joint_names]
        self.model = pin.buildReducedModel(full, lock, pin.neutral(full)) if lock else full
        self.data = self.model.createData()
        self.base = self.model.getFrameId(base)
        self.tip = self.model.getFrameId(tip)
        # our joint order (base to tip) -> Pinocchio's q index
        self.names = list(joint_names)
        self.index = [self.model.joints[self.model.getJointId(n)].idx_q for n in joint_names]

    def q(self, q_ours: np.ndarray) -> np.ndarray:
        q = pin.neutral(self.model)
        q[self.index] = q_ours
        return q

    def tip_in_base(self, q_ours: np.ndarray) -> np.ndarray:
        pin.framesForwardKinematics(self.model, self.data, self.q(q_ours))
        base = self.data.oMf[self.base]
        return (base.inverse() * self.data.oMf[self.tip]).homogeneous

    def gravity(self, q_ours: np.ndarray, g: np.ndarray) -> np.ndarray:
        self.model.gravity.linear = g
        tau = pin.computeGeneralizedGravity(self.model, self.data, self.q(q_ours))
        return tau[[self.model.joints[self.model.getJointId(n)].idx_v for n in self.names]]

    def mass_matrix(self, q_ours: np.ndarray) -> np.ndarray:
        M = pin.crba(self.model, self.data, self.q(q_ours))
        M = np.triu(M) + np.triu(M, 1).T
        v = [self.model.joints[self.model.getJointId(n)].idx_v for n in self.names]
        return M[np.ix_(v, v)]
