"""The units a joint's findings are stated in: a revolute joint's (rad, N m) or a prismatic
joint's (m, N). One table, so the fit texts, the sensor findings and the JSON agree."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class JointUnits:
    kind: str           # "revolute" or "prismatic"
    position: str
    velocity: str
    effort: str         # torque or force at the joint
    damping: str        # viscous friction
    stiffness: str
    small_position: str     # for play and steps: mrad or mm (1e-3 of the position unit)


REVOLUTE = JointUnits("revolute", "rad", "rad/s", "N m", "N m s/rad", "N m/rad", "mrad")
PRISMATIC = JointUnits("prismatic", "m", "m/s", "N", "N s/m", "N/m", "mm")


def units_of(kind: str) -> JointUnits:
    return PRISMATIC if kind == "prismatic" else REVOLUTE


def parameter_units(kind: str) -> dict[str, str]:
    """Plant-file parameter name -> its unit on a joint of this kind."""
    u = units_of(kind)
    return {"coulomb_friction": u.effort, "viscous_friction": u.damping, "stribeck_friction": u.effort,
            "stribeck_velocity": u.velocity, "gravity_torque": u.effort, "gravity_angle": "rad",
            "torque_limit_joint": u.effort, "feedback_latency_cycles": "cycles", "backlash": u.position,
            "joint_stiffness": u.stiffness, "quantum": u.position}
