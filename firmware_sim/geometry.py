"""The arm's true geometry inside the simulator: the nominal arm file plus hidden errors.

The controller only ever sees the nominal arm file; the plant's camera, laser ranger and
contact world place the tool with this model, so calibration, the closed-loop approach and
the sim-vs-real tool have a real absolute error to find. Errors are SI (m, rad), per joint in
bus order, added to the arm file's D-H rows; base and tool offsets are composed on the right
of the nominal frames (xyz in m, roll-pitch-yaw in rad).
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
from pydantic import Field

from spacearm.base.paths import REPO_ROOT
from spacearm.base.config.loader import StrictModel
from spacearm.base.kinematics.model import KinematicModel, load_model
from spacearm.base.spatial import xyz_rpy_to_transform

DEFAULT_ARM = "configs/arm/oru_testbed_6dof.toml"

Vec3 = tuple[float, float, float]
PerJoint = tuple[float, ...]   # tuples keep the model hashable for the cache below
_ERR = dict(default=(), max_length=12)


class GeometryErrors(StrictModel):
    arm: str = Field(default=DEFAULT_ARM, description="arm TOML the truth starts from (repo-relative or absolute)")
    da: PerJoint = Field(**_ERR, description="m, added to a_i")
    dalpha: PerJoint = Field(**_ERR, description="rad, added to alpha_i")
    dd: PerJoint = Field(**_ERR, description="m, added to d_i")
    dtheta: PerJoint = Field(**_ERR, description="rad, added to the joint zero (theta offset)")
    dbeta: PerJoint = Field(**_ERR, description="rad, Hayati beta about y")
    base_xyz: Vec3 = (0.0, 0.0, 0.0)
    base_rpy: Vec3 = (0.0, 0.0, 0.0)
    tool_xyz: Vec3 = (0.0, 0.0, 0.0)
    tool_rpy: Vec3 = (0.0, 0.0, 0.0)
    thermal_expansion: float = Field(default=0.0, ge=0.0, le=1.0e-3,
                                     description="1/K link growth (a, d and tool offset) with the plant's "
                                                 "temperature profile; aluminium 2.3e-5; off = 0")

    def arm_path(self) -> Path:
        path = Path(self.arm)
        return path if path.is_absolute() else REPO_ROOT / path

    def true_model(self, temperature_delta: float = 0.0) -> KinematicModel:
        """The arm as built, at `temperature_delta` K from the profile's reference."""
        if self.thermal_expansion == 0.0 or temperature_delta == 0.0:
            return _true_model(self)
        # 0.01 K steps keep the cache small; 2e-5/K * 0.01 K on 2 m is 0.4 um.
        return _expanded_model(self, round(self.thermal_expansion * temperature_delta, 7))


def _padded(values: PerJoint, n: int) -> np.ndarray:
    out = np.zeros(n)
    out[:min(n, len(values))] = values[:n]
    return out


@lru_cache(maxsize=16)
def _true_model(errors: GeometryErrors) -> KinematicModel:
    nominal = load_model(errors.arm_path())
    n = nominal.nq
    return nominal.with_errors(
        da=_padded(errors.da, n), dalpha=_padded(errors.dalpha, n), dd=_padded(errors.dd, n),
        dtheta=_padded(errors.dtheta, n),
        dbeta=_padded(errors.dbeta, n) if any(errors.dbeta) else None,
        base=nominal.base @ xyz_rpy_to_transform(errors.base_xyz, errors.base_rpy),
        tool=nominal.tool @ xyz_rpy_to_transform(errors.tool_xyz, errors.tool_rpy))


@lru_cache(maxsize=64)
def _expanded_model(errors: GeometryErrors, strain: float) -> KinematicModel:
    """Every link length (a, d and the tool offset) grown by the thermal strain."""
    model = _true_model(errors)
    n = model.nq
    tool = model.tool.copy()
    tool[:3, 3] *= 1.0 + strain
    return model.with_errors(da=strain * np.asarray(model.a), dalpha=np.zeros(n), dd=strain * np.asarray(model.d),
                             dtheta=np.zeros(n), tool=tool)
