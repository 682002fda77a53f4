"""Joint friction at the link side: Coulomb + viscous + Stribeck (static rise at low speed).

    f(v) = sign(v) * (Fc + Fs * exp(-(v / vs)^2)) + b * v

Near zero speed the joint sticks while the applied torque stays below the static level
Fc + Fs (handled by the integrator in ``spacearm.firmware_sim.plant``).
"""
from __future__ import annotations

import math


def friction_torque(v: float, coulomb: float, viscous: float, stribeck: float, stribeck_velocity: float) -> float:
    """Friction torque opposing motion at joint speed v (rad/s), N m (same sign as v)."""
    f = viscous * v
    if v != 0.0 and (coulomb > 0.0 or stribeck > 0.0):
        level = coulomb
        if stribeck > 0.0:
            level += stribeck * math.exp(-(v / stribeck_velocity) ** 2)
        f += math.copysign(level, v)
    return f


def static_friction(coulomb: float, stribeck: float) -> float:
    """Break-away torque: what it takes to start moving from rest, N m."""
    return coulomb + stribeck
