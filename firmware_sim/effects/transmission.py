"""Harmonic-drive transmission: dead band (backlash) and periodic transmission error.

Angles are in joint units (motor angle divided by the gear ratio). The transmission error
repeats ``harmonic`` times per wave-generator (motor) turn, as harmonic drives do:

    q_link = theta + A * sin(harmonic * N * theta + phase)
"""
from __future__ import annotations

import math


def dead_zone(deflection: float, backlash: float) -> float:
    """Deflection that transmits torque when the gear has a total play of `backlash` rad."""
    half = 0.5 * backlash
    if deflection > half:
        return deflection - half
    if deflection < -half:
        return deflection + half
    return 0.0


def transmission_error(theta: float, amplitude: float, harmonic: float, phase: float, gear_ratio: float) -> float:
    """Link angle minus ideal output angle, rad."""
    if amplitude == 0.0:
        return 0.0
    return amplitude * math.sin(harmonic * gear_ratio * theta + phase)


def transmission_error_slope(theta: float, amplitude: float, harmonic: float, phase: float,
                             gear_ratio: float) -> float:
    """d(transmission error)/d(theta), for the link velocity."""
    if amplitude == 0.0:
        return 0.0
    w = harmonic * gear_ratio
    return amplitude * w * math.cos(w * theta + phase)
