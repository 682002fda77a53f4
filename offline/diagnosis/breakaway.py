"""Stiction read from the breakaway torque, as a friction test on a real joint measures it.

Where a joint sticks and slips, the replays of the stiction law do not follow the recording
sample by sample, and the linear fit and its replay refinement put the level 40-75 % low
(a lower level with a slower decay fits the smeared slips better). The recording shows the
level directly: at each start from rest and each reversal the drive's torque rises until the
joint breaks free, so the torque residual (recording - nominal replay) peaks at the level
then. The median over the starts is the estimate. Each peak is the largest of about a second of noisy rows, so
it sits up to a noise level or two high: the standard error combines the spread over the
starts with the channel's noise, and the estimate replaces the fitted level only where it
is clearly higher, by a share and by more than twice the noise.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from spacearm.offline.diagnosis.fitting import ChannelFit

MOVING = 1e-3               # rad/s (m/s): the nominal replay's speed above which the joint moves
WINDOW_S = 1.0              # s after a start in which the joint breaks free
MIN_EVENTS = 5


def start_events(velocity: np.ndarray) -> np.ndarray:
    """Rows where the joint starts from rest or reverses (the nominal replay's `velocity`):
    where stiction shows as a breakaway peak."""
    moving = np.abs(velocity) > MOVING
    starts = np.flatnonzero(moving[1:] & ~moving[:-1]) + 1
    reversals = np.flatnonzero(moving[1:] & moving[:-1] & (np.sign(velocity[1:]) != np.sign(velocity[:-1]))) + 1
    return np.unique(np.r_[starts, reversals])


def breakaway_level(residual: np.ndarray, velocity: np.ndarray, rows: np.ndarray, dt: float,
                    noise: float) -> tuple[float, float, int] | None:
    """(level, standard error, starts used) from the torque `residual` and the nominal replay's
    `velocity` of one joint, over the boolean `rows`; None with fewer than MIN_EVENTS starts."""
    window = max(int(round(WINDOW_S / dt)), 2)
    peaks = []
    for e in start_events(velocity):
        end = e + window
        if end > len(residual) or not rows[e:end].all():
            continue
        direction = np.sign(velocity[min(e + 2, len(velocity) - 1)])
        peaks.append(float(np.max(direction * residual[e:end])))
    if len(peaks) < MIN_EVENTS:
        return None
    spread = 1.2533 * float(np.std(peaks)) / math.sqrt(len(peaks))     # standard error of a median
    return float(np.median(peaks)), math.hypot(spread, noise), len(peaks)


BREAKAWAY_RATIO = 1.5       # breakaway level / fitted level above which the joint is taken to stick and slip ...
BREAKAWAY_MARGIN = 2.0      # ... and by more than this many noise levels


def at_breakaway(fit: ChannelFit, residual: np.ndarray, velocity: np.ndarray, train: np.ndarray, dt: float,
                 noise: float) -> ChannelFit:
    """A Stribeck fit with its level read from the training rows' breakaway torque where that
    is clearly higher (the fitted level then belongs to smeared slips) and the held-out rows'
    starts confirm it (their own breakaway level agrees within the 95 % interval of the
    difference, and is itself clearly above zero); otherwise the fit as it is. The decay speed
    stays the fit's. Such a fit is judged by its breakaway, not sample by sample: replays of
    stick-slip do not follow a recording row by row even with the true plant."""
    if fit.effects != ("stribeck",):
        return fit
    found = breakaway_level(residual, velocity, train, dt, noise)
    level = float(fit.coef[0])
    if found is None or found[0] <= BREAKAWAY_RATIO * level or found[0] - level <= BREAKAWAY_MARGIN * noise:
        return fit
    held = breakaway_level(residual, velocity, ~train, dt, noise)
    if held is None or held[0] < 1.96 * held[1] or abs(held[0] - found[0]) > 1.96 * math.hypot(found[1], held[1]):
        return fit
    return replace(fit, coef=np.array([found[0]]), stderr=np.array([found[1]]), judged_by="breakaway",
                   rms_heldout_before=held[0], rms_heldout_after=abs(held[0] - found[0]))
