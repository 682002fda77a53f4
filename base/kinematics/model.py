"""Kinematic model (immutable parameters) and data (per-call scratch), Pinocchio style.

Both D-H conventions are reduced to one chain of fixed transforms and joint rotations,

    T(q) = F_0 Rz(theta_1) F_1 Rz(theta_2) ... Rz(theta_n) F_n,   theta_i = q_i + theta_offset_i,

so FK, the Jacobian and the analytic IK never branch on the convention.
  standard (with Hayati beta): A_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i) Ry(beta_i)
  modified (Craig):            T_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Ry(beta_i) Rz(theta_i) Tz(d_i)
The joint-i axis is the z axis of the frame just before Rz(theta_i). A prismatic joint adds
Tz(q_i) right after Rz(theta_i) (its theta stays at theta_offset_i, q adds to d_i); Rz and Tz
commute, so both conventions keep the same chain.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from spacearm.base.config.arm import ArmConfig, FixedFrame, load_arm_config
from spacearm.base.spatial import rotx, roty, rotz, trans, xyz_rpy_to_transform

Array = NDArray[np.float64]


def _frozen(x: ArrayLike, shape: tuple[int, ...] | None = None) -> Array:
    arr = np.array(x, dtype=float)
    if shape is not None and arr.shape != shape:
        raise ValueError(f"expected shape {shape}, got {arr.shape}")
    arr.setflags(write=False)
    return arr


def dh_head(convention: str, a: float, alpha: float, beta: float) -> Array:
    """Fixed part before Rz(theta): identity (standard) or Rx(alpha) Tx(a) Ry(beta) (modified)."""
    if convention == "standard":
        return np.eye(4)
    return rotx(alpha) @ trans(a, 0.0, 0.0) @ roty(beta)


def dh_tail(convention: str, a: float, alpha: float, d: float, beta: float) -> Array:
    """Fixed part after Rz(theta): Tz(d) Tx(a) Rx(alpha) Ry(beta) (standard) or Tz(d) (modified)."""
    if convention == "standard":
        return trans(0.0, 0.0, d) @ trans(a, 0.0, 0.0) @ rotx(alpha) @ roty(beta)
    return trans(0.0, 0.0, d)


def dh_transform(convention: str, a: float, alpha: float, d: float, theta: float,
                 beta: float = 0.0) -> Array:
    """One full D-H link transform in the given convention."""
    return dh_head(convention, a, alpha, beta) @ rotz(theta) @ dh_tail(convention, a, alpha, d, beta)


def fixed_frame_transform(frame: FixedFrame, convention: str) -> Array:
    """4x4 of a config FixedFrame (a D-H row in the arm's convention, or xyz + rpy)."""
    if frame.dh is not None:
        r = frame.dh
        return dh_transform(convention, r.a, r.alpha, r.d, r.theta)
    return xyz_rpy_to_transform(frame.xyz, frame.rpy)


@dataclass(frozen=True, eq=False)
class KinematicModel:
    """Immutable kinematic parameters of a serial arm (SI units, rad).

    The arrays are read-only; use `with_errors` or `dataclasses.replace` for a modified copy.
    `F` (n+1, 4, 4) and `tails` (n, 4, 4) are derived: T = F_0 prod_i Rz(theta_i) F_i, and link
    frame i = (F_0 ... F_{i-1} product up to joint i) Rz(theta_i) tails_i.
    """
    convention: str
    a: Array
    alpha: Array
    d: Array
    theta_offset: Array
    beta: Array
    beta_mask: NDArray[np.bool_]
    base: Array
    tool: Array
    q_min: Array
    q_max: Array
    v_max: Array
    a_max: Array
    j_max: Array
    q_home: Array
    joint_names: tuple[str, ...]
    name: str = "arm"
    joint_types: tuple[str, ...] = ()   # "revolute"/"prismatic" per joint; empty = all revolute
    F: Array = field(init=False, repr=False)
    tails: Array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if self.convention not in ("standard", "modified"):
            raise ValueError(f"convention must be 'standard' or 'modified', got {self.convention!r}")
        n = len(self.joint_names)
        for name in ("a", "alpha", "d", "theta_offset", "beta", "q_min", "q_max", "v_max",
                     "a_max", "j_max", "q_home"):
            object.__setattr__(self, name, _frozen(getattr(self, name), (n,)))
        mask = np.array(self.beta_mask, dtype=bool)
        mask.setflags(write=False)
        object.__setattr__(self, "beta_mask", mask)
        object.__setattr__(self, "base", _frozen(self.base, (4, 4)))
        object.__setattr__(self, "tool", _frozen(self.tool, (4, 4)))
        object.__setattr__(self, "joint_names", tuple(self.joint_names))
        types = tuple(self.joint_types) or ("revolute",) * n
        if len(types) != n or any(t not in ("revolute", "prismatic") for t in types):
            raise ValueError(f"joint_types must be {n} of 'revolute'/'prismatic', got {types}")
        object.__setattr__(self, "joint_types", types)
        heads = [dh_head(self.convention, self.a[i], self.alpha[i], self.beta[i]) for i in range(n)]
        tails = [dh_tail(self.convention, self.a[i], self.alpha[i], self.d[i], self.beta[i])
                 for i in range(n)]
        F = np.empty((n + 1, 4, 4))
        F[0] = self.base @ heads[0]
        for i in range(1, n):
            F[i] = tails[i - 1] @ heads[i]
        F[n] = tails[n - 1] @ self.tool
        object.__setattr__(self, "F", _frozen(F))
        object.__setattr__(self, "tails", _frozen(np.array(tails)))

    @property
    def nq(self) -> int:
        """Number of joints."""
        return len(self.joint_names)

    @property
    def prismatic(self) -> NDArray[np.bool_]:
        """Mask of the prismatic joints (a new array)."""
        return np.array([t == "prismatic" for t in self.joint_types], dtype=bool)

    @property
    def reach(self) -> float:
        """Upper bound of the arm's reach (sum of link lengths, offsets and strokes), m."""
        stroke = np.where(self.prismatic, np.maximum(np.abs(self.q_min), np.abs(self.q_max)), 0.0)
        return float(np.abs(self.a).sum() + np.abs(self.d).sum() + stroke.sum()
                     + np.linalg.norm(self.base[:3, 3]) + np.linalg.norm(self.tool[:3, 3]))

    @classmethod
    def from_config(cls, config: ArmConfig, calibrated: bool = True) -> "KinematicModel":
        """Build the model from a validated arm file, with its [calibration] corrections
        unless `calibrated` is False."""
        conv = config.arm.convention
        joints = config.joints
        model = cls(
            convention=conv,
            a=[j.a for j in joints],
            alpha=[j.alpha for j in joints],
            d=[j.d for j in joints],
            theta_offset=[j.theta_offset for j in joints],
            beta=[0.0 if j.beta is None else j.beta for j in joints],
            beta_mask=[j.beta is not None for j in joints],
            base=fixed_frame_transform(config.base, conv),
            tool=fixed_frame_transform(config.tool, conv),
            q_min=[j.limits.lower for j in joints],
            q_max=[j.limits.upper for j in joints],
            v_max=[j.limits.velocity for j in joints],
            a_max=[j.limits.acceleration for j in joints],
            j_max=[j.limits.jerk for j in joints],
            q_home=[j.home for j in joints],
            joint_names=[j.name for j in joints],
            name=config.arm.name,
            joint_types=tuple(j.type for j in joints),
        )
        c = config.calibration
        if c is None or not calibrated:
            return model
        return model.with_errors(dtheta=c.dtheta or None, dalpha=c.dalpha or None, da=c.da or None,
                                 dd=c.dd or None, dbeta=c.dbeta or None,
                                 base=_corrected(model.base, c.dbase), tool=_corrected(model.tool, c.dtool))

    def with_errors(self, *, dtheta: ArrayLike | None = None, dalpha: ArrayLike | None = None,
                    da: ArrayLike | None = None, dd: ArrayLike | None = None,
                    dbeta: ArrayLike | None = None, base: ArrayLike | None = None,
                    tool: ArrayLike | None = None) -> "KinematicModel":
        """Copy with D-H parameter errors added (dtheta adds to theta_offset).

        A nonzero dbeta on a joint without beta marks beta as modelled there. `base`/`tool`
        replace the fixed frames (4x4). Joint limits are unchanged.
        """
        n = self.nq

        def add(value: Array, delta: ArrayLike | None) -> Array:
            return value if delta is None else value + np.broadcast_to(np.asarray(delta, float), (n,))

        beta = add(self.beta, dbeta)
        mask = self.beta_mask if dbeta is None else (
            self.beta_mask | (np.broadcast_to(np.asarray(dbeta, float), (n,)) != 0.0))
        return dataclasses.replace(
            self, theta_offset=add(self.theta_offset, dtheta), alpha=add(self.alpha, dalpha),
            a=add(self.a, da), d=add(self.d, dd), beta=beta, beta_mask=mask,
            base=self.base if base is None else base, tool=self.tool if tool is None else tool)

    def random_configurations(self, count: int, rng: np.random.Generator | None = None,
                              margin: float = 0.0) -> Array:
        """Uniform random joint vectors (count, n) within limits shrunk by `margin` rad."""
        rng = np.random.default_rng() if rng is None else rng
        return rng.uniform(self.q_min + margin, self.q_max - margin, size=(count, self.nq))

    def within_limits(self, q: ArrayLike, tol: float = 0.0) -> bool:
        """True when every joint lies inside [q_min - tol, q_max + tol]."""
        q = np.asarray(q, dtype=float)
        return bool(np.all(q >= self.q_min - tol) and np.all(q <= self.q_max + tol))


def _corrected(frame: Array, delta: list[float]) -> Array | None:
    """frame Tx Ty Tz Rx Ry Rz (delta), or None (unchanged) without a correction."""
    if not delta:
        return None
    x, y, z, rx, ry, rz = delta
    return frame @ trans(x, y, z) @ rotx(rx) @ roty(ry) @ rotz(rz)


def load_model(path: str | Path) -> KinematicModel:
    """Load an arm file (configs/arm/*.toml) into a KinematicModel."""
    return KinematicModel.from_config(load_arm_config(path))


class KinematicData:
    """Preallocated scratch for one model: chain frames, Jacobian, work arrays.

    Not thread safe; use one per thread. Results returned by the algorithms may be views
    into this object (documented per function) and are overwritten by the next call.
    The geometry copied in here belongs to `self.model`; the algorithms call `bind` whenever
    they are handed another model (an identity check per call), so data never carries another
    model's geometry into a result.
    """

    def __init__(self, model: KinematicModel) -> None:
        n = model.nq
        self.nq = n
        self.model = model
        # A[i] = Rz(theta_{i+1}) F_{i+1}; rows 2, 3 never change, rows 0, 1 are
        # [[c, -s], [s, c]] @ F_{i+1}[:2]. That 2x2 block is cos() of the angle block
        # [[th, th + pi/2], [th - pi/2, th]], so one add, one cos and one batched matmul
        # build all of A (each numpy call costs ~1 us here; fewer calls is what matters).
        self.A = np.empty((n, 4, 4))
        self.angles = np.empty((n, 2, 2))
        self.rot2 = np.empty((n, 2, 2))
        self.A_top = self.A[:, :2, :]
        # B[0] = F_0, B[i] = B[i-1] A[i-1]; joint i+1 axis is z of B[i]; B[n] is the end pose.
        self.B = np.empty((n + 1, 4, 4))
        # Jacobian stored transposed (row per joint) so the cross product writes contiguously.
        self.Jt = np.empty((n, 6))
        self.J = self.Jt.T
        # Axis and lever arm, each with the first two columns repeated so that the cross
        # product is three slices (no fancy indexing): [x y z x y].
        self.zext = np.empty((n, 5))
        self.dext = np.empty((n, 5))
        self.cross_a = np.empty((n, 3))
        self.cross_b = np.empty((n, 3))
        self._A_views = [self.A[i] for i in range(n)]
        self._B_views = [self.B[i] for i in range(n + 1)]
        # Views used by the Jacobian, built once (creating a view costs ~0.3 us).
        self._axes = self.B[:n, :3, 2]
        self._origins = self.B[:n, :3, 3]
        self._p_end = self.B[n, :3, 3]
        self._z3, self._z_wrap, self._z_head = self.zext[:, :3], self.zext[:, 3:], self.zext[:, :2]
        self._d3, self._d_wrap, self._d_head = self.dext[:, :3], self.dext[:, 3:], self.dext[:, :2]
        self._z_12, self._z_20 = self.zext[:, 1:4], self.zext[:, 2:5]
        self._d_12, self._d_20 = self.dext[:, 1:4], self.dext[:, 2:5]
        self._Jv, self._Jw = self.Jt[:, :3], self.Jt[:, 3:]
        # Prismatic joints: A[i][2, 3] = F_{i+1}[2, 3] + q_i (Tz(q) before F only shifts row 2).
        self._A_z = self.A[:, 2, 3]
        self.q_rev = np.empty(n)
        self.q_pri = np.empty(n)
        self.bind(model)

    def bind(self, model: KinematicModel) -> None:
        """Copy `model`'s geometry into this scratch (same number of joints required)."""
        if model.nq != self.nq:
            raise ValueError(f"kinematic data for {self.nq} joints used with a {model.nq}-joint model "
                             f"({model.name!r})")
        self.model = model
        self.A[:, 2:, :] = model.F[1:, 2:, :]
        self.F_top = np.ascontiguousarray(model.F[1:, :2, :])
        self.F_z = np.ascontiguousarray(model.F[1:, 2, 3])
        self.angle_shift = (model.theta_offset[:, None, None]
                            + np.array([[0.0, 0.5 * np.pi], [-0.5 * np.pi, 0.0]]))
        self.B[0] = model.F[0]
        self.prismatic = model.prismatic
        self.has_prismatic = bool(self.prismatic.any())
        self.revolute = (~self.prismatic).astype(float)
        self.prismatic_f = self.prismatic.astype(float)
