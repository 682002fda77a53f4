"""Geometric Jacobian at the tool point, in the base frame: rows (v; omega), shape (6, n)."""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from spacearm.base.kinematics.forward import compute_chain
from spacearm.base.kinematics.model import KinematicData, KinematicModel

Array = NDArray[np.float64]


def jacobian_from_chain(data: KinematicData) -> Array:
    """Jacobian from the frames already in data.B (after compute_chain). Returns data.J (a view).

    Column i: (z_i x (p - o_i); z_i) with z_i, o_i the axis and origin of the frame just
    before Rz(theta_i); with Hayati beta that frame already includes the previous Ry(beta).
    """
    np.copyto(data._z3, data._axes)
    np.copyto(data._z_wrap, data._z_head)
    np.subtract(data._p_end, data._origins, out=data._d3)
    np.copyto(data._d_wrap, data._d_head)
    # (z x d)_k = z_{k+1} d_{k+2} - z_{k+2} d_{k+1}, indices mod 3: the [x y z x y] copies
    # make both shifted operands plain slices.
    np.multiply(data._z_12, data._d_20, out=data.cross_a)
    np.multiply(data._z_20, data._d_12, out=data.cross_b)
    np.subtract(data.cross_a, data.cross_b, out=data._Jv)
    np.copyto(data._Jw, data._z3)
    if data.has_prismatic:   # a sliding joint moves the tool along its axis and does not turn it
        data._Jv[data.prismatic] = data._z3[data.prismatic]
        data._Jw[data.prismatic] = 0.0
    return data.J


def fk_jacobian(model: KinematicModel, data: KinematicData, q: ArrayLike) -> tuple[Array, Array]:
    """End pose (4x4) and Jacobian (6, n); both are views into data, valid until the next call."""
    compute_chain(model, data, q)
    return data.B[-1], jacobian_from_chain(data)


def jacobian(model: KinematicModel, data: KinematicData, q: ArrayLike) -> Array:
    """Geometric Jacobian (6, n) at q (a new array)."""
    compute_chain(model, data, q)
    return jacobian_from_chain(data).copy()
