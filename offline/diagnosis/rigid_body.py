"""The user's arm as a rigid-body model from its URDF (Pinocchio): inverse dynamics and the
joint torque regressor reduced to base parameters, so that link mass / centre of mass /
payload errors are fitted only in the combinations a recording can identify.

    model = load_arm(urdf, n_joints)        # extra joints (fingers) locked at 0
    tau = inverse_dynamics(model, q, dq, ddq)
    base = base_parameters(model, q, dq, ddq)   # columns of the regressor that are independent
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spacearm.offline.diagnosis.recording_io import RecordingFormatError

INERTIAL_NAMES = ("m", "mcx", "mcy", "mcz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")   # Pinocchio's order


@dataclass
class ArmModel:
    model: object            # pinocchio.Model
    data: object             # pinocchio.Data (scratch)
    joint_names: list[str]
    source: str

    @property
    def n(self) -> int:
        return int(self.model.nv)


def load_arm(urdf: str | Path, n_joints: int) -> ArmModel:
    """The URDF's first `n_joints` moving joints; any further ones (a gripper's fingers) are
    locked at zero. One clear error for files Pinocchio cannot read."""
    import pinocchio as pin
    path = Path(urdf)
    if not path.is_file():
        raise RecordingFormatError(f"{path}: no such URDF file")
    try:
        model = pin.buildModelFromUrdf(str(path))
    except Exception as exc:    # Pinocchio raises plain RuntimeErrors (and ValueErrors) for bad XML
        raise RecordingFormatError(f"{path}: not a URDF Pinocchio can read ({str(exc).splitlines()[0][:160]})") \
            from None
    if model.nq != model.nv:
        raise RecordingFormatError(f"{path}: continuous or spherical joints are not supported (nq {model.nq} != "
                                   f"nv {model.nv})")
    if model.nv < n_joints:
        raise RecordingFormatError(f"{path}: {model.nv} moving joints, the recording has {n_joints}")
    if model.nv > n_joints:
        locked = list(range(n_joints + 1, model.njoints))
        model = pin.buildReducedModel(model, locked, pin.neutral(model))
    return ArmModel(model, model.createData(), [model.names[i] for i in range(1, model.njoints)], str(path))


def inverse_dynamics(arm: ArmModel, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> np.ndarray:
    import pinocchio as pin
    return np.array([pin.rnea(arm.model, arm.data, q[k], dq[k], ddq[k]) for k in range(len(q))])


def regressor(arm: ArmModel, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> np.ndarray:
    """(rows, n, 10 n): joint torques are linear in the links' inertial parameters."""
    import pinocchio as pin
    return np.array([pin.computeJointTorqueRegressor(arm.model, arm.data, q[k], dq[k], ddq[k])
                     for k in range(len(q))])


def parameter_names(arm: ArmModel) -> list[str]:
    links = [arm.model.names[i] for i in range(1, arm.model.njoints)]
    return [f"{name}.{p}" for name in links for p in INERTIAL_NAMES]


def base_columns(Y: np.ndarray, tol: float = 1e-6) -> list[int]:
    """Independent regressor columns (QR with column pivoting on a stacked sample): the base
    parameters are these, with the other columns' effect folded into them."""
    from scipy.linalg import qr
    stacked = Y.reshape(-1, Y.shape[-1])
    scale = np.linalg.norm(stacked, axis=0)
    keep = np.flatnonzero(scale > tol * max(float(scale.max()), 1e-300))
    if len(keep) == 0:
        return []
    _, r, piv = qr(stacked[:, keep] / scale[keep], mode="economic", pivoting=True)
    diag = np.abs(np.diag(r))
    rank = int(np.sum(diag > tol * diag[0])) if len(diag) else 0
    return sorted(int(keep[i]) for i in piv[:rank])
