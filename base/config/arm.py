"""Schema of an arm file (configs/arm/*.toml): D-H table, limits, fixed frames.

All quantities are SI (m, rad, s, N m). The papers' tables are in mm and degrees; the
TOML files carry the converted values with the paper's figures in comments.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator

from spacearm.base.config.limits import ApproachConfig, SupervisionConfig
from spacearm.base.config.inertia import LinkInertial, UrdfSource
from spacearm.base.config.loader import StrictModel, load_toml_model

TWO_PI = 2.0 * math.pi
# Longest link we accept: 30 m (SSRMS booms are 7.1 m). Catches mm-for-m mistakes.
MAX_LENGTH_M = 30.0


class JointLimits(StrictModel):
    lower: float = Field(ge=-3 * TWO_PI, le=3 * TWO_PI, description="rad")
    upper: float = Field(ge=-3 * TWO_PI, le=3 * TWO_PI, description="rad")
    velocity: float = Field(gt=0.0, le=10.0, description="rad/s")
    acceleration: float = Field(gt=0.0, le=100.0, description="rad/s^2")
    jerk: float = Field(gt=0.0, le=10000.0, description="rad/s^3")

    @model_validator(mode="after")
    def _ordered(self) -> "JointLimits":
        if not self.lower < self.upper:
            raise ValueError(f"lower ({self.lower}) must be less than upper ({self.upper})")
        return self


class DriveLimits(StrictModel):
    """What the joint's drive allows, as opposed to what the planner asks (JointLimits).

    The defaults are the ORU test bed's drives (1 rad/s, 150 N m, 1 deg following error);
    an imported arm takes velocity and effort from its URDF."""
    velocity: float = Field(default=1.0, gt=0.0, le=50.0, description="rad/s (m/s if prismatic)")
    torque: float = Field(default=150.0, gt=0.0, le=1.0e5, description="N m (N if prismatic)")
    following_error: float = Field(default=0.0175, gt=0.0, le=1.0, description="rad (m if prismatic)")


class Joint(StrictModel):
    name: str = Field(min_length=1, max_length=64)
    type: Literal["revolute", "prismatic"] = Field(
        default="revolute", description="prismatic: q (m) adds to d, theta_offset stays fixed")
    a: float = Field(ge=-MAX_LENGTH_M, le=MAX_LENGTH_M, description="m")
    alpha: float = Field(ge=-TWO_PI, le=TWO_PI, description="rad")
    d: float = Field(ge=-MAX_LENGTH_M, le=MAX_LENGTH_M, description="m")
    theta_offset: float = Field(default=0.0, ge=-TWO_PI, le=TWO_PI, description="rad")
    beta: float | None = Field(default=None, ge=-TWO_PI, le=TWO_PI,
                               description="Hayati rotation about y, rad; None when not modelled")
    home: float = Field(default=0.0, ge=-3 * TWO_PI, le=3 * TWO_PI, description="rad (m if prismatic)")
    limits: JointLimits
    rated_torque: float = Field(default=150.0, gt=0.0, le=1.0e5, description="N m (N if prismatic)")
    drive: DriveLimits = Field(default_factory=lambda: DriveLimits(),
                               description="the drive's own limits (supervision, simulator, diagnosis)")

    @model_validator(mode="after")
    def _home_inside_limits(self) -> "Joint":
        if not self.limits.lower <= self.home <= self.limits.upper:
            raise ValueError(
                f"home ({self.home}) must lie within limits [{self.limits.lower}, {self.limits.upper}]")
        return self


class DHRow(StrictModel):
    a: float = Field(default=0.0, ge=-MAX_LENGTH_M, le=MAX_LENGTH_M, description="m")
    alpha: float = Field(default=0.0, ge=-TWO_PI, le=TWO_PI, description="rad")
    d: float = Field(default=0.0, ge=-MAX_LENGTH_M, le=MAX_LENGTH_M, description="m")
    theta: float = Field(default=0.0, ge=-TWO_PI, le=TWO_PI, description="rad")


class FixedFrame(StrictModel):
    """A constant transform, either as a D-H row (in the arm's convention) or xyz + rpy.

    rpy is roll-pitch-yaw about fixed x, y, z (R = Rz(yaw) Ry(pitch) Rx(roll)).
    """
    dh: DHRow | None = None
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @model_validator(mode="after")
    def _one_form(self) -> "FixedFrame":
        if self.dh is not None and (any(self.xyz) or any(self.rpy)):
            raise ValueError("give either dh or xyz/rpy, not both")
        if any(abs(v) > MAX_LENGTH_M for v in self.xyz):
            raise ValueError(f"xyz components must be within +-{MAX_LENGTH_M} m")
        return self


class Plane(StrictModel):
    """A plane n . p + f = 0 in the base frame (n need not be unit; it is normalised)."""
    normal: tuple[float, float, float]
    offset: float

    @model_validator(mode="after")
    def _nonzero(self) -> "Plane":
        if math.hypot(*self.normal) < 1e-9:
            raise ValueError("normal must not be zero")
        return self


class Sensors(StrictModel):
    resolver_accuracy: float = Field(default=1.2120342e-4, gt=0.0, le=0.1,
                                     description="rad (25 arcsec by default)")


class CartesianLimits(StrictModel):
    """Limits of straight-line tool moves (the tool frame's origin and orientation)."""
    linear_velocity: float = Field(default=0.05, gt=0.0, le=2.0, description="m/s")
    linear_acceleration: float = Field(default=0.1, gt=0.0, le=10.0, description="m/s^2")
    angular_velocity: float = Field(default=0.1, gt=0.0, le=3.0, description="rad/s")
    angular_acceleration: float = Field(default=0.2, gt=0.0, le=30.0, description="rad/s^2")


class ArmInfo(StrictModel):
    name: str = Field(min_length=1)
    description: str = ""
    source: str = ""
    convention: Literal["standard", "modified"]
    total_length: float | None = Field(default=None, gt=0.0, le=100.0, description="m")
    payload: float | None = Field(default=None, ge=0.0, le=1.0e5, description="kg")


class Calibration(StrictModel):
    """Identified corrections to the nominal rows above, with where they came from.

    Written by `spacearm calibrate ... --apply`; the kinematic model adds them to the nominal
    D-H values (per joint, bus order), so the nominal rows stay readable and the correction
    can be removed by deleting this table."""
    method: str = Field(min_length=1, description="e.g. 'laser-ranger plane, weighted LM'")
    date: str = Field(min_length=1, description="UTC, ISO 8601")
    data: str = Field(default="", description="measurement file the fit used")
    configurations: int = Field(default=0, ge=0)
    residual_rms: float = Field(default=0.0, ge=0.0, description="m, identification residual RMS")
    validation_rms_before: float | None = Field(default=None, ge=0.0, description="m, held-out residual RMS, nominal")
    validation_rms_after: float | None = Field(default=None, ge=0.0, description="m, held-out residual RMS, calibrated")
    dtheta: list[float] = Field(default_factory=list, max_length=12, description="rad")
    dalpha: list[float] = Field(default_factory=list, max_length=12, description="rad")
    da: list[float] = Field(default_factory=list, max_length=12, description="m")
    dd: list[float] = Field(default_factory=list, max_length=12, description="m")
    dbeta: list[float] = Field(default_factory=list, max_length=12, description="rad")
    # Small-motion corrections of the fixed frames, applied after them: x, y, z (m), rx, ry, rz
    # (rad) as Tx Ty Tz Rx Ry Rz (the identification's frame parameters, calibration/errormodel.py).
    dbase: list[float] = Field(default_factory=list, max_length=6, description="m, m, m, rad, rad, rad")
    dtool: list[float] = Field(default_factory=list, max_length=6, description="m, m, m, rad, rad, rad")

    @model_validator(mode="after")
    def _small(self) -> "Calibration":
        for name in ("dbase", "dtool"):
            values = getattr(self, name)
            if values and len(values) != 6:
                raise ValueError(f"{name} needs 6 values (x, y, z in m, rx, ry, rz in rad), got {len(values)}")
            if any(abs(v) > 1.0 for v in values[:3]) or any(abs(v) > 0.5 for v in values[3:]):
                raise ValueError(f"{name}: frame corrections above 1 m / 0.5 rad are not a calibration; check units")
        for name in ("dtheta", "dalpha", "dbeta"):
            if any(abs(v) > 0.1 for v in getattr(self, name)):
                raise ValueError(f"{name}: corrections above 0.1 rad are not a calibration; check units")
        for name in ("da", "dd"):
            if any(abs(v) > 0.1 for v in getattr(self, name)):
                raise ValueError(f"{name}: corrections above 0.1 m are not a calibration; check units (m)")
        return self


class ArmConfig(StrictModel):
    arm: ArmInfo
    joints: list[Joint] = Field(min_length=1, max_length=12)
    base: FixedFrame = FixedFrame()
    tool: FixedFrame = FixedFrame()
    sensors: Sensors = Sensors()
    cartesian: CartesianLimits = CartesianLimits()
    plane: Plane | None = None
    postures: dict[str, list[float]] = Field(default_factory=dict,
                                             description="named joint postures, rad")
    calibration: Calibration | None = None
    supervision: SupervisionConfig = SupervisionConfig()
    approach: ApproachConfig = ApproachConfig()
    urdf: UrdfSource | None = None
    links: list[LinkInertial] = Field(default_factory=list, max_length=12,
                                      description="one inertial per joint (rigid-body plant); empty = none")

    @model_validator(mode="after")
    def _unique_names(self) -> "ArmConfig":
        names = [j.name for j in self.joints]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise ValueError(f"joint names must be unique; repeated: {', '.join(duplicates)}")
        for name, q in self.postures.items():
            if len(q) != len(self.joints):
                raise ValueError(f"posture {name!r} has {len(q)} values, the arm has {len(self.joints)} joints")
            for joint, value in zip(self.joints, q):
                if not joint.limits.lower <= value <= joint.limits.upper:
                    raise ValueError(f"posture {name!r}: {joint.name} = {value} is outside "
                                     f"[{joint.limits.lower}, {joint.limits.upper}]")
        if self.links and len(self.links) != len(self.joints):
            raise ValueError(f"links has {len(self.links)} entries, the arm has {len(self.joints)} joints")
        if self.calibration is not None:
            for name in ("dtheta", "dalpha", "da", "dd", "dbeta"):
                values = getattr(self.calibration, name)
                if values and len(values) != len(self.joints):
                    raise ValueError(f"calibration.{name} has {len(values)} values, the arm has "
                                     f"{len(self.joints)} joints")
        return self


def load_arm_config(path: str | Path) -> ArmConfig:
    return load_toml_model(path, ArmConfig)
