"""URDF chain -> arm file (configs/arm/*.toml): modified D-H rows, limits, drive limits, inertials.

The D-H rows come from the URDF's joint axes at q = 0 (base/kinematics/dh_from_axes.py),
the base and tool frames carry the rest of the geometry as xyz + rpy, and `[[links]]` holds
each moving joint's rigid body expressed in its D-H link frame (fixed links folded in). The
URDF stays referenced in `[urdf]` for meshes. FK of the result agrees with the URDF
(tests/kinematics/test_urdf_import.py checks it against Pinocchio).

Planner limits are ours, as for the papers' arms: half the URDF's velocity limit, at most
0.5 rad/s (or m/s), acceleration 2 /s times that, jerk 10 /s times the acceleration. The
URDF's velocity and effort limits become the drive limits.
"""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w
from pydantic import ValidationError

from spacearm.base.config.arm import ArmConfig
from spacearm.base.kinematics.dh_from_axes import fit_modified_dh
from spacearm.base.kinematics.jacobian import jacobian
from spacearm.base.kinematics.model import KinematicData, KinematicModel
from spacearm.base.spatial import inv_transform, matrix_to_rpy
from spacearm.base.kinematics.urdf import Chain, UrdfError, read_chain, transform_body

CONTINUOUS_RANGE = 2.0 * math.pi   # rad each way for a continuous joint (one turn of cable wrap)
PLANNER_VELOCITY_CAP = 0.5         # rad/s (m/s)
READY_CANDIDATES = 400             # random postures tried for the well-conditioned "ready"


def _clean(x: float) -> float:
    """Round-off below 1e-15 to 0 so the file reads as the geometry (never changes FK by > 1e-15)."""
    return 0.0 if abs(x) < 1e-15 else float(x)


def _limits(chain: Chain, i: int) -> tuple[float, float]:
    joint = chain.joints[i]
    if joint.type == "continuous" or joint.lower is None or joint.upper is None:
        if joint.type == "prismatic":
            raise UrdfError(f"{chain.path}: prismatic joint {joint.name!r} has no <limit lower upper>")
        return -CONTINUOUS_RANGE, CONTINUOUS_RANGE
    return joint.lower, joint.upper


def _joint_table(chain: Chain, i: int, row: Any) -> dict[str, Any]:
    joint = chain.joints[i]
    lower, upper = _limits(chain, i)
    home = 0.0 if lower <= 0.0 <= upper else 0.5 * (lower + upper)   # URDF zero, else mid-range
    urdf_velocity = joint.velocity if joint.velocity and joint.velocity > 0.0 else 1.0
    velocity = min(0.5 * urdf_velocity, PLANNER_VELOCITY_CAP)
    effort = joint.effort if joint.effort and joint.effort > 0.0 else 150.0
    table: dict[str, Any] = {
        "name": joint.name,
        "type": "prismatic" if joint.type == "prismatic" else "revolute",
        "a": _clean(row.a), "alpha": _clean(row.alpha), "d": _clean(row.d),
        "theta_offset": _clean(row.theta),
        "home": home,
        "rated_torque": effort,
        "limits": {"lower": lower, "upper": upper, "velocity": velocity,
                   "acceleration": 2.0 * velocity, "jerk": 20.0 * velocity},
        "drive": {"velocity": min(urdf_velocity, 50.0), "torque": effort},
    }
    if row.hayati:
        table["beta"] = 0.0
    return table


def _frame_table(T: np.ndarray) -> dict[str, Any]:
    return {"xyz": [_clean(v) for v in T[:3, 3]], "rpy": [_clean(v) for v in matrix_to_rpy(T[:3, :3])]}


def _ready(model: KinematicModel, seed: int = 0) -> list[float]:
    """A posture near home with the best-conditioned Jacobian (the checkout's Cartesian moves)."""
    rng = np.random.default_rng(seed)
    data = KinematicData(model)
    span = np.minimum(model.q_max - model.q_min, 2.0)
    lo = np.maximum(model.q_min + 0.1 * span, model.q_home - 0.5 * span)
    hi = np.minimum(model.q_max - 0.1 * span, model.q_home + 0.5 * span)
    best, best_q = -1.0, model.q_home
    for q in rng.uniform(lo, hi, size=(READY_CANDIDATES, model.nq)):
        sigma = float(np.linalg.svd(jacobian(model, data, q), compute_uv=False)[-1])
        if sigma > best:
            best, best_q = sigma, q
    return [float(v) for v in best_q]


def import_arm(urdf: str | Path, base: str, tip: str, out: str | Path | None = None,
               name: str | None = None) -> tuple[dict[str, Any], ArmConfig]:
    """Arm-file data (a dict for TOML) and its validated config for the URDF chain base -> tip.

    `out` is where the file will be written; the `[urdf] file` is made relative to it."""
    urdf = Path(urdf)
    chain = read_chain(urdf, base, tip)
    points = [pose[:3, 3] for pose in chain.joint_poses]
    fit = fit_modified_dh(points, chain.axes)
    joints = [_joint_table(chain, i, row) for i, row in enumerate(fit.rows)]
    tool = inv_transform(fit.frames[-1]) @ chain.tip_pose
    where = Path(out).resolve().parent if out is not None else Path.cwd()
    data: dict[str, Any] = {
        "arm": {"name": name or urdf.stem, "convention": "modified",
                "description": f"imported from {urdf.name}, chain {base} -> {tip}",
                "source": f"URDF {urdf.name} (spacearm arm import)"},
        "urdf": {"file": os.path.relpath(urdf.resolve(), where), "base": base, "tip": tip},
        "base": _frame_table(fit.base),
        "tool": _frame_table(tool),
        "joints": joints,
    }
    if all(body is not None for body in chain.bodies):
        links = []
        for body, frame in zip(chain.bodies, fit.frames):
            local = transform_body(body, inv_transform(frame))
            I = local.inertia
            links.append({"mass": float(local.mass), "com": [_clean(v) for v in local.com],
                          "inertia": [_clean(v) for v in (I[0, 0], I[0, 1], I[0, 2], I[1, 1], I[1, 2], I[2, 2])]})
        data["links"] = links
    model = KinematicModel.from_config(_validated(urdf, data))
    data["postures"] = {"home": [float(v) for v in model.q_home], "ready": _ready(model)}
    return data, _validated(urdf, data)


def _validated(urdf: Path, data: dict[str, Any]) -> ArmConfig:
    try:
        return ArmConfig.model_validate(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"])
        raise UrdfError(f"{urdf}: the imported arm is not a valid arm file: {where}: {first['msg']}") from None


def arm_toml(data: dict[str, Any], command: str) -> str:
    """TOML text of imported arm data with a header saying how it was made."""
    header = (f"# Arm file written by `{command}` (base/kinematics/arm_import.py).\n"
              "# Modified D-H (Craig) rows derived from the URDF's joint axes at q = 0; base and tool\n"
              "# frames are xyz + rpy (R = Rz(yaw) Ry(pitch) Rx(roll)); SI units (m, rad, kg).\n"
              "# Planner limits: half the URDF velocity (<= 0.5 rad/s), acceleration 2x, jerk 20x that.\n"
              "# Drive limits: the URDF's velocity and effort. [[links]]: inertials in each D-H link frame.\n\n")
    return header + tomli_w.dumps(data)
