"""Kinematics core: model/data split, FK (single and batched), Jacobian, IK, pose errors.

Typical use::

    model = load_model("configs/arm/oru_testbed_6dof.toml")
    data = KinematicData(model)
    T = fk(model, data, q)
    J = jacobian(model, data, q)
    result = solve_ik(model, data, T_target, q_seed)
"""
from spacearm.base.kinematics.analytic_ik import analytic_ik, analytic_solver, expand_wraps
from spacearm.base.kinematics.forward import compute_chain, fk, fk_batch, frames
from spacearm.base.kinematics.inverse import IKResult, ik_fixed_joint, solve_dls, solve_ik
from spacearm.base.kinematics.jacobian import fk_jacobian, jacobian
from spacearm.base.kinematics.model import KinematicData, KinematicModel, dh_transform, load_model
from spacearm.base.kinematics.pose_error import (pose_errors_batch, position_error, rotation_error,
                                              to_mm, twist_error, wrap_angle)
from spacearm.base.spatial import (matrix_to_rotvec, matrix_to_rpy, rotvec_to_matrix,
                                              rpy_to_matrix)

__all__ = [
    "KinematicModel", "KinematicData", "load_model", "dh_transform",
    "compute_chain", "fk", "frames", "fk_batch", "fk_jacobian", "jacobian",
    "IKResult", "solve_dls", "solve_ik", "ik_fixed_joint",
    "analytic_ik", "analytic_solver", "expand_wraps",
    "position_error", "rotation_error", "twist_error", "pose_errors_batch", "to_mm", "wrap_angle",
    "rpy_to_matrix", "matrix_to_rpy", "rotvec_to_matrix", "matrix_to_rotvec",
]
