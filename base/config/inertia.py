"""Link inertials and the URDF an arm was imported from (sections of an arm file).

`[[links]]` gives one rigid body per joint, expressed in that joint's D-H link frame (the frame
after the joint's D-H row, as `spacearm.base.kinematics.frames` returns it), so an arm without a
URDF can still be simulated with coupled rigid-body dynamics. `[urdf]` records where an
imported arm came from; the URDF stays the reference for meshes.
"""
from __future__ import annotations

from pydantic import Field, model_validator

from spacearm.base.config.loader import StrictModel


class LinkInertial(StrictModel):
    """One link's mass, centre of mass and inertia about the centre of mass (link frame axes)."""
    mass: float = Field(ge=0.0, le=1.0e5, description="kg")
    com: tuple[float, float, float] = Field(default=(0.0, 0.0, 0.0), description="m, in the link frame")
    inertia: tuple[float, float, float, float, float, float] = Field(
        default=(0.0,) * 6, description="kg m^2 about the com: ixx, ixy, ixz, iyy, iyz, izz")

    @model_validator(mode="after")
    def _physical(self) -> "LinkInertial":
        if any(abs(c) > 30.0 for c in self.com):
            raise ValueError("com components must be within +-30 m (check units: m)")
        ixx, ixy, ixz, iyy, iyz, izz = self.inertia
        if min(ixx, iyy, izz) < 0.0:
            raise ValueError("principal moments ixx, iyy, izz must not be negative")
        # triangle inequality of a real body's moments (small slack for rounded URDF values)
        slack = 1e-6 * max(ixx + iyy + izz, 1e-12)
        if ixx + iyy < izz - slack or iyy + izz < ixx - slack or izz + ixx < iyy - slack:
            raise ValueError("inertia violates the triangle inequality (ixx + iyy >= izz, ...)")
        return self


class UrdfSource(StrictModel):
    """Where an imported arm came from: URDF file (relative to the arm file) and the chain."""
    file: str = Field(min_length=1)
    base: str = Field(min_length=1, description="URDF link the arm's base frame is")
    tip: str = Field(min_length=1, description="URDF link the arm's tool frame is")
