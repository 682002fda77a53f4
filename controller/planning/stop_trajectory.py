"""A stop planned from the state the arm is in: every joint from its velocity to rest, all on
one path.

All joints share one speed scale sigma(t), falling from 1 to 0: q(t) = q0 + v0 S(t) with S the
integral of sigma, so the joints keep their velocity ratios (the tool stays on the tangent of
its path, it does not swerve) and no commanded speed is ever above the speed at the stop.
The scale's deceleration is the largest every joint allows (min a_j / |v0_j|); it is reached
in one control period (jerk a / period) and let go the same way, so the stop takes v/a + one
period and travels v^2/2a + half a period's travel. The arm file's motion jerk limit is not
used: its S-curve would add v a / 2j (17 mrad, a third more, on the ORU test bed) to every
stopping distance, and a stop is the one motion where distance matters more than jerk.
"""
from __future__ import annotations

import math

import numpy as np

from spacearm.controller.planning.joint_move import JointSetpoint

RESTING = 1e-6   # rad/s: a joint slower than this is already at rest


class StopTrajectory:
    def __init__(self, q0: np.ndarray, v0: np.ndarray, a_max: np.ndarray, period: float):
        self.q0 = np.asarray(q0, float).copy()
        self.v0 = np.asarray(v0, float).copy()
        moving = np.abs(self.v0) > RESTING
        if not moving.any():
            self.v0[:] = 0.0
            self.duration = 0.0
            self._phases = (0.0, 0.0, 0.0)
            return
        self.v0[~moving] = 0.0
        accel = float(np.min(np.asarray(a_max, float)[moving] / np.abs(self.v0[moving])))   # 1/s on sigma
        jerk = accel / period
        if accel * period <= 1.0:
            ramp, peak = period, accel
            cruise = 1.0 / accel - period
        else:      # so slow that the ramps alone stop it: a triangle in deceleration
            ramp = math.sqrt(1.0 / jerk)
            peak, cruise = jerk * ramp, 0.0
        self._jerk, self._peak = jerk, peak
        self._phases = (ramp, cruise, ramp)
        self.duration = 2.0 * ramp + cruise

    def scale(self, t: float) -> tuple[float, float, float]:
        """(S, sigma, dsigma/dt) at t s after the stop."""
        ramp, cruise, _ = self._phases
        if self.duration == 0.0:
            return 0.0, 0.0, 0.0
        t = min(max(t, 0.0), self.duration)
        j, a = self._jerk, self._peak
        if t <= ramp:
            return t - j * t ** 3 / 6.0, 1.0 - j * t * t / 2.0, -j * t
        s1, v1 = ramp - j * ramp ** 3 / 6.0, 1.0 - j * ramp * ramp / 2.0
        if t <= ramp + cruise:
            tau = t - ramp
            return s1 + v1 * tau - a * tau * tau / 2.0, v1 - a * tau, -a
        s2, v2 = s1 + v1 * cruise - a * cruise * cruise / 2.0, v1 - a * cruise
        tau = t - ramp - cruise
        sigma = max(0.0, v2 - a * tau + j * tau * tau / 2.0)
        return s2 + v2 * tau - a * tau * tau / 2.0 + j * tau ** 3 / 6.0, sigma, -a + j * tau

    def sample(self, t: float) -> JointSetpoint:
        s, sigma, dsigma = self.scale(t)
        return JointSetpoint(self.q0 + self.v0 * s, self.v0 * sigma, self.v0 * dsigma)

    @property
    def rest(self) -> np.ndarray:
        return self.sample(self.duration).q
