"""Temperature over a run: piecewise-linear (t, degC) points, e.g. an orbit's day/night swing.

The laser-ranger paper quotes about 2 mm of thermal growth on a 2 m arm over the orbital
temperature range; with aluminium links (2.3e-5 /K) that is a swing of about 43 K.
"""
from __future__ import annotations

import numpy as np
from pydantic import Field, field_validator

from spacearm.base.config.loader import StrictModel


class TemperatureProfile(StrictModel):
    reference: float = Field(default=20.0, ge=-150.0, le=200.0, description="degC at which the geometry is nominal")
    points: tuple[tuple[float, float], ...] = Field(
        default=(), max_length=10000, description="(t s, degC) pairs, t increasing; empty = reference throughout")

    @field_validator("points")
    @classmethod
    def _increasing(cls, points):
        times = [p[0] for p in points]
        if any(b <= a for a, b in zip(times, times[1:])):
            raise ValueError("times must increase")
        if any(not -150.0 <= p[1] <= 200.0 for p in points):
            raise ValueError("temperatures must lie in [-150, 200] degC")
        return points

    def at(self, t: float) -> float:
        if not self.points:
            return self.reference
        times, temps = zip(*self.points)
        return float(np.interp(t, times, temps))

    def delta(self, t: float) -> float:
        return self.at(t) - self.reference
