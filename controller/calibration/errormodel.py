"""Kinematic error model: named parameter vector, batched FK and analytic parameter Jacobian.

The arm is rewritten as one product of elementary motions

    W_nom [Tx Ty Tz Rx Ry Rz](world) * prod_i joint_i * T_tool_nom [Tx Ty Tz Rx Ry Rz](tool)

  standard joint i:  Rz(q_i + theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i) Ry(beta_i)
  modified joint i:  Rx(alpha_i) Tx(a_i) Ry(beta_i) Rz(q_i + theta_i) Tz(d_i)

(modified rows store a_{i-1}, alpha_{i-1} on joint i, as `KinematicModel` does). Every
elementary motion carries one named parameter, so the derivative of the end pose with
respect to it is the unit twist of that motion's axis: a rotation about unit axis u through
point o moves the end point p by u x (p - o) and turns it by u; a translation moves it by u.
That is the whole analytic identification Jacobian, evaluated for N configurations at once.

The world frame (`world_prefix`, e.g. "base" or "board") and the tool frame ("tool", "cam")
are 6-parameter small-motion frames after their nominal transforms; their nominal values are
0, so they express corrections of the mount and target frames.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from spacearm.base.kinematics import KinematicModel
from spacearm.base.spatial import rotx, roty, rotz, trans
from spacearm.controller.calibration.joint_load import JointLoad

Array = NDArray[np.float64]

DH_KINDS = ("theta", "d", "a", "alpha", "beta")
COMPLIANCE = "k"       # joint compliance parameters k_1..k_n (rad/(N m) or m/N)
FRAME_KINDS = ("x", "y", "z", "rx", "ry", "rz")
_AXIS = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True)
class Op:
    """One elementary motion: rotation ('R') or translation ('T') about/along local axis."""
    kind: str          # 'R' or 'T'
    axis: int          # 0, 1, 2
    param: int         # index into the parameter vector
    joint: int = -1    # joint index whose q adds to the value (theta, or d of a prismatic joint)


@dataclass(frozen=True, eq=False)
class ErrorModel:
    """Parameterised forward kinematics of `kin`, with named parameters (SI, rad).

    names/nominal cover every candidate parameter (D-H of all joints incl. beta, world and tool
    frames). Which ones are estimated is decided by identifiability / the caller (free masks).
    """
    kin: KinematicModel
    world_nominal: Array
    tool_nominal: Array
    world_prefix: str = "base"
    tool_prefix: str = "tool"
    load: JointLoad | None = None    # gravity load per joint: adds the compliances k_1..k_n
    names: tuple[str, ...] = field(init=False)
    nominal: Array = field(init=False)
    ops: tuple[Op, ...] = field(init=False, repr=False)
    pre: Array = field(init=False, repr=False)    # fixed transform before the world params
    mid: Array = field(init=False, repr=False)    # fixed transform before the tool params

    def __post_init__(self) -> None:
        kin = self.kin
        names: list[str] = []
        nominal: list[float] = []
        ops: list[Op] = []

        def add(name: str, value: float, kind: str, axis: int, joint: int = -1) -> None:
            names.append(name)
            nominal.append(float(value))
            ops.append(Op(kind, axis, len(names) - 1, joint))

        for k in FRAME_KINDS:
            add(f"{self.world_prefix}_{k}", 0.0, "R" if k.startswith("r") else "T", _AXIS[k[-1]])
        prismatic = prismatic_joints(kin)
        for i in range(kin.nq):
            j = i + 1
            th, d, a, al, be = (kin.theta_offset[i], kin.d[i], kin.a[i], kin.alpha[i], kin.beta[i])
            # The joint variable adds to theta (revolute) or to d (prismatic); the other one is a
            # constant whose error is identified the same way.
            jt, jd = (-1, i) if prismatic[i] else (i, -1)
            if kin.convention == "standard":
                add(f"theta_{j}", th, "R", 2, jt)
                add(f"d_{j}", d, "T", 2, jd)
                add(f"a_{j}", a, "T", 0)
                add(f"alpha_{j}", al, "R", 0)
                add(f"beta_{j}", be, "R", 1)
            else:
                add(f"alpha_{j}", al, "R", 0)
                add(f"a_{j}", a, "T", 0)
                add(f"beta_{j}", be, "R", 1)
                add(f"theta_{j}", th, "R", 2, jt)
                add(f"d_{j}", d, "T", 2, jd)
        for k in FRAME_KINDS:
            add(f"{self.tool_prefix}_{k}", 0.0, "R" if k.startswith("r") else "T", _AXIS[k[-1]])
        if self.load is not None:
            # Compliances carry no motion of their own: they scale the joint's motion by its load.
            names += [f"{COMPLIANCE}_{i + 1}" for i in range(kin.nq)]
            nominal += [0.0] * kin.nq
        object.__setattr__(self, "names", tuple(names))
        object.__setattr__(self, "nominal", np.array(nominal))
        object.__setattr__(self, "ops", tuple(ops))
        object.__setattr__(self, "pre", np.asarray(self.world_nominal, float) @ kin.base)
        object.__setattr__(self, "mid", kin.tool @ np.asarray(self.tool_nominal, float))

    @classmethod
    def from_kinematics(cls, kin: KinematicModel, world: ArrayLike | None = None,
                        tool: ArrayLike | None = None, world_prefix: str = "base",
                        tool_prefix: str = "tool", load: JointLoad | None = None) -> "ErrorModel":
        """Error model of `kin`; `world` is prepended to kin.base, `tool` appended to kin.tool;
        with `load`, a compliance per joint (joint elasticity, see joint_load.py)."""
        return cls(kin, np.eye(4) if world is None else np.asarray(world, float),
                   np.eye(4) if tool is None else np.asarray(tool, float), world_prefix, tool_prefix, load)

    # ----------------------------------------------------------------------------- naming
    @property
    def n_params(self) -> int:
        return len(self.names)

    def index(self, names: str | list[str] | tuple[str, ...]) -> NDArray[np.int_] | int:
        """Index (or indices) of parameter name(s)."""
        lookup = {n: i for i, n in enumerate(self.names)}
        if isinstance(names, str):
            return lookup[names]
        missing = [n for n in names if n not in lookup]
        if missing:
            raise KeyError(f"unknown parameters: {missing}")
        return np.array([lookup[n] for n in names], dtype=int)

    def dh_names(self, kinds: tuple[str, ...] = ("theta", "d", "a", "alpha"),
                 with_beta: bool = True) -> list[str]:
        """D-H parameter names joint by joint (beta only where the arm models it)."""
        out = []
        for i in range(self.kin.nq):
            out += [f"{k}_{i + 1}" for k in kinds]
            if with_beta and self.kin.beta_mask[i] and "beta" not in kinds:
                out.append(f"beta_{i + 1}")
        return out

    def frame_names(self, which: str) -> list[str]:
        prefix = self.world_prefix if which == "world" else self.tool_prefix
        return [f"{prefix}_{k}" for k in FRAME_KINDS]

    def with_errors(self, errors: dict[str, float]) -> Array:
        """Full parameter vector: nominal plus the named errors."""
        p = self.nominal.copy()
        for name, value in errors.items():
            p[self.index(name)] += value
        return p

    # --------------------------------------------------------------------------- evaluate
    def poses(self, p: ArrayLike, Q: ArrayLike) -> Array:
        """End poses (N, 4, 4) for parameter vector p and configurations Q (N, n)."""
        return self._run(np.asarray(p, float), np.atleast_2d(np.asarray(Q, float)), False)[0]

    def poses_and_jacobian(self, p: ArrayLike, Q: ArrayLike) -> tuple[Array, Array]:
        """End poses (N, 4, 4) and d(pose)/dp as base-frame twists at the end point (N, 6, P).

        Rows 0-2: dp/dparam (m per unit), rows 3-5: rotation vector per unit.
        """
        return self._run(np.asarray(p, float), np.atleast_2d(np.asarray(Q, float)), True)

    def _run(self, p: Array, Q: Array, want_jac: bool) -> tuple[Array, Array | None]:
        N = Q.shape[0]
        T = np.empty((N, 3, 4))
        T[:] = self.pre[:3]
        P = self.n_params
        if want_jac:
            axes = np.zeros((N, P, 3))
            origins = np.zeros((N, P, 3))
            is_rot = np.zeros(P, dtype=bool)
        tool_start = len(self.ops) - len(FRAME_KINDS)
        if self.load is not None:
            tau = self.load.torques(Q)
            k0 = len(self.ops)                       # the compliances follow the tool frame
        for op in self.ops:
            if op.param == tool_start:
                T = T @ self.mid
            value = p[op.param] + (Q[:, op.joint] if op.joint >= 0 else 0.0)
            if self.load is not None and op.joint >= 0:
                value = value + p[k0 + op.joint] * tau[:, op.joint]
            if want_jac:
                axes[:, op.param] = T[:, :, op.axis]
                origins[:, op.param] = T[:, :, 3]
                is_rot[op.param] = op.kind == "R"
            if op.kind == "T":
                T[:, :, 3] += T[:, :, op.axis] * np.reshape(value, (-1, 1))
            else:
                i, j = {0: (1, 2), 1: (2, 0), 2: (0, 1)}[op.axis]
                c = np.reshape(np.cos(value), (-1, 1))
                s = np.reshape(np.sin(value), (-1, 1))
                ci, cj = T[:, :, i].copy(), T[:, :, j]
                T[:, :, i] = c * ci + s * cj
                T[:, :, j] = c * cj - s * ci
        out = np.zeros((N, 4, 4))
        out[:, :3] = T
        out[:, 3, 3] = 1.0
        if not want_jac:
            return out, None
        J = np.empty((N, 6, P))
        lever = T[:, None, :, 3] - origins                                 # (N, P, 3)
        rot = np.cross(axes, lever)
        J[:, :3, :] = np.where(is_rot[None, :, None], rot, axes).transpose(0, 2, 1)
        J[:, 3:, :] = np.where(is_rot[None, :, None], axes, 0.0).transpose(0, 2, 1)
        if self.load is not None:
            # d pose / d k_j = (the joint's own motion) * tau_j
            for op in self.ops:
                if op.joint >= 0:
                    J[:, :, k0 + op.joint] = J[:, :, op.param] * tau[:, op.joint, None]
        return out, J

    # -------------------------------------------------------------------- back to kinematics
    def to_kinematics(self, p: ArrayLike) -> KinematicModel:
        """A KinematicModel equal to this error model at p (world/tool frames folded in)."""
        p = np.asarray(p, float)
        kin = self.kin
        n = kin.nq
        get = lambda k: np.array([p[self.index(f"{k}_{i + 1}")] for i in range(n)])  # noqa: E731
        base = self.pre @ _frame(p[self.index(self.frame_names("world"))])
        tool = self.mid @ _frame(p[self.index(self.frame_names("tool"))])
        beta = get("beta")
        return dataclasses.replace(kin, theta_offset=get("theta"), d=get("d"), a=get("a"),
                                   alpha=get("alpha"), beta=beta,
                                   beta_mask=kin.beta_mask | (beta != 0.0), base=base, tool=tool)


def prismatic_joints(kin: KinematicModel) -> NDArray[np.bool_]:
    """Which joints are prismatic: the model's `joint_types` ('P'/'prismatic') or `prismatic`
    mask when it has one (URDF import adds them), else all revolute."""
    types = getattr(kin, "joint_types", None)
    if types is not None:
        return np.array([str(t).lower() in ("p", "prismatic") for t in types], bool)
    mask = getattr(kin, "prismatic", None)
    return np.zeros(kin.nq, bool) if mask is None else np.asarray(mask, bool)


def _frame(v: Array) -> Array:
    """Tx Ty Tz Rx Ry Rz (v = x, y, z, rx, ry, rz) as a 4x4, same order as the ops."""
    return trans(*v[:3]) @ rotx(v[3]) @ roty(v[4]) @ rotz(v[5])
