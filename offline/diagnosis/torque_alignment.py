"""A time offset between a recording's torque column and its motion columns (q, dq).

A real arm's logger may stamp the joint-torque sensor and the (estimated, filtered) joint
velocity a few milliseconds apart. The inverse dynamics then pairs each torque with a
slightly older or newer motion, and the error is proportional to the torque's rate of change:
on a heavy joint it looks like a negative viscous friction and moves the fitted Coulomb level
by tens of percent (the Panda recording of Gaz et al., URDF bodies: joint 2's Coulomb friction
0.20 N m before, 0.15 N m after a 5 ms alignment, their least-squares identification 0.141 N m;
its viscous friction -0.03 before, 0.2 N m s/rad after, theirs 0.21).

The offset is the shift, on a sub-sample grid, that best fits the
training rows with each moving joint's rigid-body torque plus Coulomb, viscous and offset
terms, with the motion (q, dq, q'') shifted onto the torque's clock (one shift for all joints).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from spacearm.offline.diagnosis.fitting import SIGNIFICANCE, correlation_length

MAX_OFFSET_S = 0.03          # searched both ways; a longer offset would be a different motion
MIN_SAMPLES = 3              # ... and at least this many sampling periods
STEP_S = 0.001               # grid of the search (finer than a 100 Hz recording's period)
# The offset is a nuisance parameter of the friction fit, estimated with it as least squares would:
# it is applied where the pooled held-out RMS falls by MIN_GAIN and no joint's rises by more than
# its noise; it is called significant (a sensor finding) only with p < SIGNIFICANCE. On the real
# Panda it moves joint 2's Coulomb level by 40 % yet lowers the pooled held-out RMS by only 2 %.
MIN_GAIN = 0.01
AT_REST = 1e-3               # rad/s: the sign of slower motion is not trusted for Coulomb friction


@dataclass
class TimeOffset:
    seconds: float               # > 0: the torque column is ahead of the motion columns
    heldout_gain: float          # share the pooled held-out RMS falls by
    searched_s: float            # the largest offset searched (both ways)
    p_value: float               # of the training misfit's drop, over blocks of correlated rows

    @property
    def significant(self) -> bool:
        return self.p_value < SIGNIFICANCE

    @property
    def text(self) -> str:
        lead = "ahead of" if self.seconds > 0 else "behind"
        weight = "" if self.significant else (
            f"; weak evidence on its own (p = {self.p_value:.2g}: the residual stays correlated over long "
            "stretches), but friction sizes depend on it, so they are fitted at the best offset")
        return (f"time offset between channels: the torque column is {1e3 * abs(self.seconds):.3g} ms {lead} the "
                f"motion columns (q, dq) (held-out torque RMS {100 * self.heldout_gain:.0f} % lower with it; searched "
                f"+-{1e3 * self.searched_s:.3g} ms){weight}; the motion is re-aligned before the physics is fitted")


def shifted(t: np.ndarray, x: np.ndarray, seconds: float) -> np.ndarray:
    """Columns x(t - seconds). A phase shift of the (mirror-extended, so seamless) columns,
    not an interpolation: linear interpolation between samples averages them, and a
    half-sample shift would win on its lower noise alone. Only smooth columns are shifted
    (the motion and the torque the rigid body needs for it), never the measured torque: a
    friction step in it would ring."""
    if seconds == 0.0:
        return x
    dt = float(np.median(np.diff(t)))
    tau = x
    x = np.concatenate([tau, tau[::-1]], axis=0)
    w = 2 * np.pi * np.fft.rfftfreq(len(x), dt)
    out = np.fft.irfft(np.fft.rfft(x, axis=0) * np.exp(-1j * w * seconds)[:, None], len(x), axis=0)
    return out[: len(tau)]


def _friction_misfit(r: np.ndarray, v: np.ndarray, train: np.ndarray, active: list[int],
                     edge: np.ndarray) -> tuple[float, np.ndarray, int]:
    """(training SSE, held-out RMS per active joint, longest correlation of the training
    residuals in rows) of per-joint Coulomb + viscous + offset."""
    sse, held, block = 0.0, [], 1
    fit_rows = train & edge
    test_rows = ~train & edge
    for j in active:
        X = np.column_stack([np.where(np.abs(v[:, j]) > AT_REST, np.sign(v[:, j]), 0.0), v[:, j],
                             np.ones(len(v))])
        coef, *_ = np.linalg.lstsq(X[fit_rows], r[fit_rows, j], rcond=None)
        e = r[:, j] - X @ coef
        sse += float(e[fit_rows] @ e[fit_rows])
        held.append(math.sqrt(float(np.mean(e[test_rows] ** 2))))
        block = max(block, correlation_length(e[fit_rows]))
    return sse, np.array(held), block


def torque_time_offset(t: np.ndarray, tau: np.ndarray, tau_nominal: np.ndarray, v: np.ndarray,
                       train: np.ndarray, active: list[int], noise: list[float]) -> TimeOffset | None:
    """The offset, or None where none is clearly there (see the module's docstring)."""
    if not active or len(t) < 50:
        return None
    dt = float(np.median(np.diff(t)))
    limit = max(MAX_OFFSET_S, MIN_SAMPLES * dt)
    margin = int(math.ceil(limit / dt)) + 1
    edge = np.zeros(len(t), bool)
    edge[margin:-margin] = True          # rows whose shifted torque is interpolated, not held at the ends
    if (train & edge).sum() < 20 or (~train & edge).sum() < 20:
        return None
    grid = np.arange(-limit, limit + 1e-12, min(STEP_S, dt / 4))
    # the motion the torque column sees, d later: the rigid-body torque of the shifted motion
    # is the nominal torque shifted (it is a function of the motion at each instant)
    misfit = lambda d: _friction_misfit(tau - shifted(t, tau_nominal, -d), shifted(t, v, -d), train, active, edge)
    best = float(grid[int(np.argmin([misfit(d)[0] for d in grid]))])
    (sse0, held0, _), (sse1, held1, block) = misfit(0.0), misfit(best)
    rows = int((train & edge).sum()) * len(active)
    p_value = float(stats.chi2.sf(max(sse0 - sse1, 0.0) / max(sse1 / rows, 1e-300) / block, 1))
    pooled0, pooled1 = math.sqrt(float(np.mean(held0 ** 2))), math.sqrt(float(np.mean(held1 ** 2)))
    gain = 1.0 - pooled1 / max(pooled0, 1e-300)
    worse = any(h1 > h0 + noise[j] for j, h0, h1 in zip(active, held0, held1))
    if abs(best) < 0.5 * STEP_S or gain < MIN_GAIN or worse:
        return None
    return TimeOffset(best, gain, limit, p_value)
