"""Forward kinematics: single configuration (preallocated, low latency) and batches."""
from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from spacearm.base.kinematics.model import KinematicData, KinematicModel

Array = NDArray[np.float64]


def compute_chain(model: KinematicModel, data: KinematicData, q: ArrayLike) -> None:
    """Fill data.B with the chain frames for q (B[i] precedes joint i+1, B[n] is the end pose)."""
    if data.model is not model:
        data.bind(model)
    angles = data.angles
    if data.has_prismatic:
        np.multiply(q, data.revolute, out=data.q_rev)
        np.add(data.q_rev.reshape(-1, 1, 1), data.angle_shift, out=angles)
        np.multiply(q, data.prismatic_f, out=data.q_pri)
        np.add(data.F_z, data.q_pri, out=data._A_z)
    else:
        np.add(np.reshape(q, (-1, 1, 1)), data.angle_shift, out=angles)
    np.cos(angles, out=data.rot2)
    np.matmul(data.rot2, data.F_top, out=data.A_top)
    Bv, Av = data._B_views, data._A_views
    for i in range(data.nq):
        np.matmul(Bv[i], Av[i], out=Bv[i + 1])


def fk(model: KinematicModel, data: KinematicData, q: ArrayLike) -> Array:
    """End (tool) pose base->tool, 4x4 (a new array)."""
    compute_chain(model, data, q)
    return data.B[-1].copy()


def frames(model: KinematicModel, data: KinematicData, q: ArrayLike) -> Array:
    """All frames, shape (n+2, 4, 4): base, link frames 1..n (D-H frames), tool."""
    compute_chain(model, data, q)
    n = model.nq
    out = np.empty((n + 2, 4, 4))
    out[0] = model.base
    q = np.asarray(q, dtype=float)
    for i in range(n):
        Rz = np.eye(4)
        Rz[:2, :2] = data.rot2[i]
        if data.prismatic[i]:
            Rz[2, 3] = q[i]
        out[i + 1] = data.B[i] @ Rz @ model.tails[i]
    out[n + 1] = data.B[n]
    return out


def cos_sin(theta: Array) -> tuple[Array, Array]:
    """cos and sin of an array via tan(theta/2).

    numpy's float64 sin/cos are scalar libm calls (~20 ns each); tan is vectorised (~3 ns),
    and the half-angle identities keep errors at a few ulp (t -> inf at theta = pi is benign).
    """
    t = np.tan(0.5 * theta)
    t2 = t * t
    inv = np.add(1.0, t2)
    np.divide(1.0, inv, out=inv)
    c = np.subtract(1.0, t2, out=t2)
    c *= inv
    t *= 2.0
    t *= inv
    return c, t


def fk_batch(model: KinematicModel, Q: ArrayLike, out: Array | None = None) -> Array:
    """End poses for many configurations: Q (N, n) -> (N, 4, 4).

    The stack X (N, 3, 4) holds the top three rows of the running product. Right-multiplying
    by Rz(theta) mixes columns 0 and 1 as (col0 + i col1) * exp(-i theta), one complex multiply
    on a complex view of X; the fixed F_i is one (3N x 4) @ (4 x 4) BLAS product. No Python
    loop over N.
    """
    Q = np.asarray(Q, dtype=float)
    if Q.ndim != 2 or Q.shape[1] != model.nq:
        raise ValueError(f"Q must have shape (N, {model.nq}), got {Q.shape}")
    N = Q.shape[0]
    prismatic = model.prismatic
    c, s = cos_sin(np.where(prismatic, 0.0, Q) + model.theta_offset if prismatic.any()
                   else Q + model.theta_offset)
    E = np.empty((N, model.nq), dtype=complex)
    E.real = c
    E.imag = s
    np.negative(E.imag, out=E.imag)  # exp(-i theta)
    F = model.F
    X = np.empty((N, 3, 4))
    X[:] = F[0, :3, :]
    for i in range(model.nq):
        X.view(complex)[:, :, 0] *= E[:, i:i + 1]
        if prismatic[i]:
            X[:, :, 3] += X[:, :, 2] * Q[:, i:i + 1]   # right-multiply by Tz(q_i)
        X = (X.reshape(3 * N, 4) @ F[i + 1]).reshape(N, 3, 4)
    if out is None:
        out = np.empty((N, 4, 4))
    out[:, :3, :] = X
    out[:, 3, :] = (0.0, 0.0, 0.0, 1.0)
    return out
