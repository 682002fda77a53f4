"""A lag between a recording's position column and its velocity column, from the recording's
own kinematics: the derivative of q must be dq. No torque and no model enter.

A robot's logger may report a velocity that is not the derivative of the position it reports
at the same stamp (an observer's estimate, a filter, positions read a cycle later). The
real Panda recording of Gaz et al. (RA-L 2019) has dq/dt of q best matched by dq 5-6 ms
later on every joint: a velocity estimate lagging its position by about half a 100 Hz cycle,
below what sensor_effects' whole-cycle lag search names (two cycles without a nominal replay).

The lag is the shift of dq (phase shift on a sub-sample grid, both ways) that best matches
the low-passed derivative of q over all moving joints; it is named only where it lowers that
mismatch by MIN_GAIN on every moving joint (one clock for the whole position column).
It is named, not applied: on the Panda, putting dq back onto q's clock lowers the held-out torque
RMS of six joints (the seventh within 1e-3 N m) and removes the torque-vs-motion offset, but
the friction law chosen on joints 1 and 3 then flips between near-tied sets (BIC apart by
less than 2), so the fit stays on the recorded clocks until that choice is settled.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, filtfilt

from spacearm.offline.diagnosis.torque_alignment import shifted

MAX_LAG_S = 0.03             # searched both ways, as for the torque column
STEP_S = 0.0005
MIN_GAIN = 0.1               # share of the dq-vs-dq/dt(q) RMS the shift must remove on every moving joint
LOWPASS_HZ = 20.0


@dataclass
class VelocityLag:
    seconds: float               # > 0: dq lags (dq/dt of q at t is dq at t + seconds)
    searched_s: float
    gains: list[float]           # per moving joint: share of the dq-vs-dq/dt(q) mismatch removed

    @property
    def text(self) -> str:
        lead = "behind" if self.seconds > 0 else "ahead of"
        return (f"time offset between channels: the velocity column dq runs {1e3 * abs(self.seconds):.3g} ms {lead} "
                f"the derivative of the position column q (shifted, it matches "
                f"{100 * min(self.gains):.0f}-{100 * max(self.gains):.0f} % better on the moving joints; searched "
                f"+-{1e3 * self.searched_s:.3g} ms; named, the fit keeps the recorded clocks)")


def _mismatch(t: np.ndarray, dq_of_q: np.ndarray, dq: np.ndarray, lag: float, edge: slice) -> np.ndarray:
    """RMS per joint of dq/dt(q) against dq `lag` later."""
    return np.sqrt(np.mean((dq_of_q - shifted(t, dq, -lag))[edge] ** 2, axis=0))


def velocity_lag(t: np.ndarray, q: np.ndarray, dq: np.ndarray, active: list[int]) -> VelocityLag | None:
    """The lag, or None where the columns agree (or the recording has no own velocity column)."""
    if not active or len(t) < 100 or not np.any(dq[:, active]):
        return None
    dt = float(np.median(np.diff(t)))
    b, a = butter(4, min(LOWPASS_HZ, 0.4 / dt) * 2 * dt)
    q_a, dq_a = q[:, active], dq[:, active]
    dq_of_q = filtfilt(b, a, np.gradient(q_a, dt, axis=0), axis=0)
    dq_f = filtfilt(b, a, dq_a, axis=0)
    limit = max(MAX_LAG_S, 3 * dt)
    margin = int(math.ceil(limit / dt)) + 2
    edge = slice(margin, len(t) - margin)
    grid = np.arange(-limit, limit + 1e-12, min(STEP_S, dt / 4))
    misfit = [float(np.sum(_mismatch(t, dq_of_q, dq_f, lag, edge) ** 2)) for lag in grid]
    best = float(grid[int(np.argmin(misfit))])
    before, after = _mismatch(t, dq_of_q, dq_f, 0.0, edge), _mismatch(t, dq_of_q, dq_f, best, edge)
    gains = [float(1 - a_ / max(b_, 1e-300)) for b_, a_ in zip(before, after)]
    if abs(best) < 0.5 * STEP_S or min(gains) < MIN_GAIN:
        return None
    return VelocityLag(best, limit, gains)

