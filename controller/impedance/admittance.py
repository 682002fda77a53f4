"""Per-axis admittance dX = (F_contact - F_d) / (M s^2 + B s + K) with M = 0 (eq. 15, 20).

With M = 0 each axis is the first-order lag B dx/dt + K x = f. It is discretised exactly for
a force held over the cycle (zero-order hold): x[k] = a x[k-1] + (1 - a) f[k] / K with
a = exp(-K T / B); K = 0 gives the pure damper x[k] = x[k-1] + T f[k] / B. Both are stable
for every B > 0, K >= 0 on their own; stability in contact is checked in config.py.
"""
from __future__ import annotations

import numpy as np


class Admittance:
    def __init__(self, stiffness: np.ndarray, damping: np.ndarray, period: float):
        k = np.asarray(stiffness, float)
        b = np.asarray(damping, float)
        if np.any(b <= 0.0) or np.any(k < 0.0):
            raise ValueError("admittance needs damping > 0 and stiffness >= 0 on every axis")
        self.a = np.exp(-k * period / b)
        # Gain on the force: (1 - a)/K, with the K -> 0 limit T/B.
        with np.errstate(divide="ignore", invalid="ignore"):
            self.gain = np.where(k > 0.0, (1.0 - self.a) / np.where(k > 0.0, k, 1.0), period / b)
        self.x = np.zeros_like(k)

    def update(self, force: np.ndarray) -> np.ndarray:
        self.x = self.a * self.x + self.gain * np.asarray(force, float)
        return self.x

    def reset(self) -> None:
        self.x[:] = 0.0
