"""A gear too stiff to make the drive ring, found by the spectrum of the drive's chatter.

Against the link resolver the servo chatters (resolver quantisation), and a compliant gear
(6e4-3e5 N m/rad on the test bed) changes how: at other frequencies, harder or softer. Which
instant a chatter cycle starts is set by the joint's sub-quantum state, which no recording
gives, so the replay with the true stiffness does not follow it row by row: on four of five
such cases of development seed 7004 it lowered the held-out torque RMS by 0-4 % (2.77 ->
2.80 N m on one; 1.4-2.4x the channel's noise each), and the sample-by-sample fits
(stiff_gear.py) found nothing. Its spectrum is reproducible: the log-spectral distance
(below) between the recording and the true stiffness's replay was 0.10-0.36 on those
cases, between two equally valid nominal replays (half a quantum apart) 0.1-0.45, and
between the recording and the nominal replay 0.5-1.06. On joints with no effect the
nominal replay was the closest (0.11-0.33) and every stiffness of the range further
(0.43 and more), so a stiffness is named only where it lowers the held-out distance, on
rows it was not fitted on, by at least MIN_HELDOUT_REDUCTION.

Spectra: Welch's average of Hann-windowed periodograms of SEGMENT rows (half overlapping)
of the torque less the ideal-sensor nominal replay's (the chatter, the sensor's noise and
whatever smooth term an effect adds), compared as logs over the frequency bins; FLOOR of
the recording's mean level keeps bins where neither has power from deciding.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.signal import spectrogram

from spacearm.offline.diagnosis.direct_sim import replayed_torque
from spacearm.offline.diagnosis.fitting import ChannelFit, block_jackknife_stderr
from spacearm.offline.diagnosis.stiff_gear import CHATTER_GRID, STIFFNESS_RANGE
from spacearm.firmware_sim.plant import PlantConfig

SEGMENT = 64                 # rows (1.3 s at 50 Hz): 33 frequency bins, 36 segments in 24 s of training rows
FLOOR = 0.03                 # of the recording's mean spectral level
MIN_HELDOUT_REDUCTION = 0.5  # held-out distance: at least halved (true stiffness: 60-70 % on development cases)
# Cost only: the grid of replays is run where the training distance of the law chosen so far (or
# the nominal) exceeds this multiple of the null's (two equally valid nominal replays); the
# held-out test decides. A joint's null alone scatters (0.1-0.53 on development recordings).
SCREEN = 1.5
# The held-out distance left must be what two equally valid nominal replays differ by (NULL_MARGIN
# times it at most): a stiffness that only partly mimics another effect on the chatter is no
# explanation (stiction of 43 N m on slow ramps: 2.49 -> 0.98 at 9e5 N m/rad, the null 0.2-0.4).
NULL_MARGIN = 2.0
MIN_SEGMENTS = 4             # per part (training, held-out): fewer make no spectrum (a ten-row recording)


def periodograms(x: np.ndarray) -> np.ndarray:
    """(frequency bins, segments): one Hann-windowed periodogram per half-overlapping segment."""
    return spectrogram(x, nperseg=SEGMENT, noverlap=SEGMENT // 2, detrend="constant", window="hann")[2]


def distance(a: np.ndarray, b: np.ndarray, floor: float) -> float:
    """RMS over frequency of the log ratio of two spectra (each above `floor`)."""
    return float(np.sqrt(np.mean((np.log(a + floor) - np.log(b + floor)) ** 2)))


def screened(real: np.ndarray, model: np.ndarray, nominal: np.ndarray, null: np.ndarray, train: np.ndarray) -> bool:
    """Whether the recording's chatter spectrum (`real`: torque less the ideal-sensor nominal
    replay's) is further from the `model`'s (the nominal replay, or the replay of the law chosen
    so far) than SCREEN times the null replay's is from the `nominal` replay's. Stiction whose
    replay already chatters as the recording does leaves nothing for a gear to explain."""
    rows = np.flatnonzero(train)
    if min(len(rows), int((~train).sum())) < (MIN_SEGMENTS + 1) * SEGMENT // 2:
        return False
    p = [periodograms(x[rows]).mean(axis=1) for x in (real, model, nominal, null)]
    floor = FLOOR * float(p[0].mean())
    return distance(p[0], p[1], floor) > SCREEN * distance(p[3], p[2], floor)


def fit_spectral_gear(nominal: PlantConfig, q_cmd: np.ndarray, dt: float, q0: np.ndarray, base_tau: np.ndarray,
                      sim_tau: np.ndarray, real_tau: np.ndarray, null_tau: np.ndarray, j: int, train: np.ndarray,
                      dq_cmd: np.ndarray | None = None, rivals: tuple[np.ndarray, ...] = ()) -> ChannelFit | None:
    """Joint `j`'s stiffness from the spectrum of its chatter: `base_tau` the ideal-sensor nominal
    replay's torque, `sim_tau` the nominal replay's (with the nominal's sensors), `real_tau` the
    recording's. Replays keep the nominal's sensors (the chatter is theirs). None where no
    stiffness simulates; otherwise a fit judged by the held-out spectral distance."""
    joints = [nominal.joint_params(i) for i in range(q_cmd.shape[1])]
    train_rows = np.flatnonzero(train)
    last = int(train_rows.max()) + 1
    held_rows = np.flatnonzero(~train)
    real_train = periodograms((real_tau - base_tau)[train_rows])
    floor = FLOOR * float(real_train.mean())
    replays: dict[float, np.ndarray | None] = {}

    def plant(log_k: float) -> PlantConfig:
        js = list(joints)
        js[j] = joints[j].model_copy(update={"joint_stiffness": float(math.exp(log_k)), "torque_noise": 0.0})
        return nominal.model_copy(update={"joints": js})

    def train_spectrum(log_k: float) -> np.ndarray | None:
        if log_k not in replays:
            tau = replayed_torque(plant(log_k), q_cmd[:last], dt, q0, j, None if dq_cmd is None else dq_cmd[:last])
            replays[log_k] = None if tau is None else periodograms((tau - base_tau[:last])[train_rows]).mean(axis=1)
        return replays[log_k]

    def loss(log_k: float, segments: np.ndarray | None = None) -> float:
        model = train_spectrum(log_k)
        if model is None:
            return math.inf
        real = real_train.mean(axis=1) if segments is None else real_train[:, segments].mean(axis=1)
        return distance(real, model, floor)

    lo, hi = (math.log(v) for v in STIFFNESS_RANGE)
    grid = np.linspace(lo, hi, CHATTER_GRID)
    i = int(np.argmin([loss(float(x)) for x in grid]))
    step = grid[1] - grid[0]
    best = minimize_scalar(loss, bounds=(max(lo, grid[i] - step), min(hi, grid[i] + step)), method="bounded",
                           options={"xatol": 0.02, "maxiter": 8})
    x = float(best.x) if best.fun < loss(float(grid[i])) else float(grid[i])
    tau = replayed_torque(plant(x), q_cmd, dt, q0, j, dq_cmd)
    if tau is None or not np.isfinite(loss(x)):
        return None
    real_held = periodograms((real_tau - base_tau)[held_rows]).mean(axis=1)
    held_floor = FLOOR * float(real_held.mean())
    spectrum = lambda model: periodograms((model - base_tau)[held_rows]).mean(axis=1)
    held = lambda model: distance(real_held, spectrum(model), held_floor)
    before, after = held(sim_tau), held(tau)
    null = distance(spectrum(null_tau), spectrum(sim_tau), held_floor)
    train_before = distance(real_train.mean(axis=1), periodograms((sim_tau - base_tau)[train_rows]).mean(axis=1),
                            floor)
    at_bound = min(x - lo, hi - x) < 0.1
    significant = after <= (1.0 - MIN_HELDOUT_REDUCTION) * before and after <= NULL_MARGIN * null and \
        loss(x) < train_before and not at_bound and all(after < held(rival) for rival in rivals)
    rel = _jackknife_spread(grid, loss, len(train_rows), real_train.shape[1])
    value = float(math.exp(x))
    return ChannelFit(("elasticity",), "tau", j, np.array([value]), np.array([value * rel]), ("joint_stiffness",),
                      (float("nan"),), loss(x) ** 2, train_before ** 2, before, after, 0.0 if significant else 1.0,
                      SEGMENT, tau - sim_tau, len(train_rows), 1, judged_by="spectrum")


def _jackknife_spread(keys: np.ndarray, loss, rows: int, segments: int) -> float:
    """Delete-a-block jackknife standard error of the log stiffness (i.e. relative) over
    contiguous stretches of the `rows` training rows (fitting.block_jackknife_stderr), each
    refit on the segments left whole: the parabola through the lowest distance on the grid of
    replays (`keys`, log stiffnesses) and its neighbours. The grid, not the points the search
    added near the best: those, a few per cent apart, held each refit within a few per cent
    where the distance was flat over a factor of two (1.34e5 fitted, +- 3 %, for 9e4 N m/rad)."""
    starts = np.arange(segments) * (SEGMENT // 2)

    def refit(kept: np.ndarray) -> np.ndarray:
        whole = np.isin(starts, kept) & np.isin(starts + SEGMENT - 1, kept)
        losses = np.array([loss(float(k), whole) for k in keys])
        m = int(np.clip(np.argmin(losses), 1, len(keys) - 2))
        a, b, _ = np.polyfit(keys[m - 1:m + 2], losses[m - 1:m + 2], 2)
        top = -b / (2 * a) if a > 0 else keys[m]
        return np.array([float(np.clip(top, keys[m - 1], keys[m + 1]))])

    return float(block_jackknife_stderr(refit, np.arange(rows), 1)[0])
