"""Whether a recording separates two plant models of one joint: the test a scorer applies
before asking the diagnosis to tell them apart (Stribeck friction against the best
Coulomb + viscous law, on a slow one-speed ramp: both run at the same level, and differ only
in the breakaway at the few reversals).

Both models are replayed from half a resolver quantum away from the recording's first
position (as null_replay does): the recording fixes that start only to a quantum, and from the
recorded start the true law alone replays the servo's resolver chatter in phase, so any other
law, however close, lost 61 % of held-out RMS to it on a one-speed ramp where the two laws
run within 0.3 % of each other (72 % at 4 %: tests/diagnosis/test_stribeck_one_speed.py).
Neither model knows that phase on a real arm.

Two views of the held-out rows (the last 40 %, as the diagnosis holds out), each judged
beyond its noise: the torque RMS (the better model lowers it by at least
MIN_CONFIRMED_REDUCTION, the share the diagnosis itself needs to confirm a finding), and the
breakaway peaks at the starts and reversals (stick_slip's windows; the better model's peak
error lower by more than PEAK_Z standard errors of a peak mean, a peak scattering by about
the channel's noise). Separable where either view says so.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from spacearm.offline.diagnosis.direct_sim import simulate
from spacearm.offline.diagnosis.honesty import MIN_CONFIRMED_REDUCTION
from spacearm.offline.diagnosis.stick_slip import BREAKAWAY_S, event_peaks, peak_windows
from spacearm.offline.diagnosis.analysis import TRAIN_FRACTION

PEAK_Z = 2.0


@dataclass
class Separation:
    rms_gain: float          # 1 - held-out RMS of the first model / of the second
    peak_gain: float         # held-out peak RMS error of the second model - of the first (torque units)
    peak_limit: float        # what peak_gain must exceed
    events: int              # held-out starts and reversals

    @property
    def separable(self) -> bool:
        return self.rms_gain >= MIN_CONFIRMED_REDUCTION or self.peak_gain > self.peak_limit


def separation(table, first, second, j: int, velocity: np.ndarray, noise: float) -> Separation:
    """How much better plant `first` explains joint `j`'s held-out torque than plant `second`
    (replays of that joint); `velocity` the joint's ideal nominal replay velocity (where the
    starts and reversals are), `noise` the channel's noise."""
    rows = len(table.t)
    held = np.arange(rows) >= int(TRAIN_FRACTION * rows)
    real = table.tau[:, j]
    q0 = table.q[0].copy()
    q0[j] += 0.5 * first.joint_params(j).position_quantum
    tau = [simulate(p, table.q_cmd, table.dt, q0=q0, joints=[j], wrench=False).tau[:, 0] for p in (first, second)]
    rms = [float(np.sqrt(np.mean((real - x)[held] ** 2))) for x in tau]
    events, ends, _, _ = peak_windows(velocity, max(int(round(BREAKAWAY_S / table.dt)), 2), table.dq[:, j])
    late = held[events]
    if late.sum() == 0:
        return Separation(1.0 - rms[0] / rms[1], 0.0, math.inf, 0)
    peaks = event_peaks(real, velocity, events[late], ends[late])
    errs = [float(np.sqrt(np.mean((peaks - event_peaks(x, velocity, events[late], ends[late])) ** 2))) for x in tau]
    return Separation(1.0 - rms[0] / rms[1], errs[1] - errs[0], PEAK_Z * noise / math.sqrt(late.sum()),
                      int(late.sum()))
