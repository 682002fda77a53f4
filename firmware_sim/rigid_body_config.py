"""`[rigid_body]` of a plant file (kept apart from firmware_sim/rigid_body.py so that loading a
plant file does not import Pinocchio unless the dynamics are switched on)."""
from __future__ import annotations

from pydantic import Field

from spacearm.base.config.loader import StrictModel


class RigidBodyParams(StrictModel):
    """`[rigid_body]` of a plant file: switches the coupled dynamics on."""
    gravity: tuple[float, float, float] = Field(
        default=(0.0, 0.0, 0.0), description="m/s^2 in the arm's base frame; (0, 0, -9.81) on the ground, 0 on orbit")
    payload_mass: float | None = Field(default=None, ge=0.0, le=1.0e5,
                                       description="kg held at the tool; None = the arm file's [arm] payload")
    payload_com: tuple[float, float, float] = Field(default=(0.0, 0.0, 0.0), description="m, tool frame")
    payload_inertia: tuple[float, float, float] = Field(default=(0.0, 0.0, 0.0),
                                                        description="kg m^2 about the payload com, tool axes")
