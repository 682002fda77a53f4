"""Stiction told from Coulomb and viscous friction by the breakaway peaks, fitted by replays.

Where a joint moves at few speeds (a slow ramp back and forth, point-to-point moves), a
Stribeck law fits the running torque exactly as a Coulomb or viscous one does: the linear
fits and their BIC cannot tell them apart, and the linear Stribeck candidate loses by its
extra parameter. What separates them is at each start from rest and each reversal: the joint
sticks until the drive's torque reaches the static level (Coulomb plus Stribeck) and only
then breaks free, so the recorded torque peaks above what the running law predicts. Sample
by sample, stick-slip is no guide: the true plant's own replay sticks and slips at other
instants than the recording (resolver quantisation decides when) and its held-out RMS was
higher than a wrong Coulomb fit's (2.4 vs 1.9 N m on a development case).

So the chosen law (or the nominal, if none) is replayed and its per-event peak compared with
the recording's. Where the recording peaks clearly higher at the training rows' events, a
Stribeck law is fitted by replays of the joint (its static level and its running level at the
joint's typical speed, which set the decay speed; judged on the training events' peaks and
the smoothed running torque), and kept only where the held-out events' peaks confirm it:
they stand above the chosen law's by more than EXCESS_Z standard errors of their mean (the
stiction is there on rows the fit never saw), the fit predicts them better than the chosen
law, and the running torque no worse than RUNNING_RATIO times. A fixed ratio of the two
held-out peak errors (at most 0.6) rejected a fit of 31.8 N m (truth 33.7) at 2.7 against
3.2 N m on a development case: the last 40 % of a slow ramp holds two reversals, each peak
scattered by about a noise level, so the ratio of two such errors is mostly noise.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize

from spacearm.offline.diagnosis.breakaway import MOVING, start_events
from spacearm.offline.diagnosis.direct_sim import replayed_torque
from spacearm.offline.diagnosis.fitting import ChannelFit
from spacearm.offline.diagnosis.running_mean import running_mean

MIN_TRAIN_EVENTS = 3
MIN_HELD_EVENTS = 2
# The training events' mean peak excess over the chosen law must exceed the control windows'
# (half-way between events, where the joint runs) by this many standard errors. Peaks are
# single rows: averaged over a few, the narrow breakaway spike of a joint at a slow reversal
# vanished (0.6 instead of 2.1 N m on a development case). The replay has the resolver chatter
# too, so its peaks sit about as high by it as the recording's; what the sensor's own noise
# adds to the recording's maxima (0.3-1 N m on effect-free joints) is what the control windows
# measure, and is taken off every peak before the fit. No fixed multiple of the channel's
# noise: a joint's own chatter (6 N m on the test bed's joint 3 alone) made one far too strict.
EXCESS_Z = 2.0     # a first screen: the held-out events must confirm the fit as well
RUNNING_RATIO = 1.5         # smoothed held-out running error may grow by at most this factor
SMOOTH_ROWS = 10            # 0.2 s at 50 Hz: the running torque, without the chatter
MAX_REPLAYS = 30
# A soft servo on a slow reversal needs seconds to build the torque that breaks a sticking
# joint free (the position error grows at the commanded speed): 1 s (breakaway.py) missed the
# peak of 8.8 N m stiction at 0.014 rad/s on a development case.
BREAKAWAY_S = 3.0
STRIBECK_VELOCITY_RANGE = (0.002, 0.1)     # rad/s (m/s), where the decay speed is searched
# The window ends this long after the recorded joint breaks free (its peak is there): the rest
# of a 3 s window only adds the largest of its running rows' noise, which buried 2-4 N m of
# stiction above running friction at a slow ramp's reversals (1.5 N m noise, development seed:
# the control windows' peaks as high as the events').
BREAK_MARGIN = 10           # rows (0.2 s at 50 Hz)
RUNNING_SWING = 3.0         # noise levels: a control window's residual swinging more is no running (see below)
# ... a null taken from such windows only where the starts' median peak excess stands this many noise
# levels out (the stiction large enough to disturb the runs): one window swinging 3 N m beside 0.5
# N m peaks at the starts named 3 N m of Coulomb friction on a sine "stiction" (test_diagnosis_honesty.py)
LARGE_STICTION = 5.0
STUCK_SPEED = 1e-3          # rad/s (m/s): a recorded joint slower than this has not broken free
# A Stribeck law whose running friction at the joint's typical speed is within a tenth of its
# static level is Coulomb friction to the precision a size is stated with (15 %)
MIN_STICTION_SHARE = 0.1


def event_peaks(tau: np.ndarray, velocity: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Per window [start, end): the largest torque in the direction of the motion that follows its start."""
    out = np.empty(len(starts))
    for i, (e, end) in enumerate(zip(starts, ends)):
        direction = np.sign(velocity[min(e + 2, len(velocity) - 1)])
        out[i] = float(np.max(direction * tau[e:max(end, e + 1)]))
    return out


def broken_free(recorded: np.ndarray, direction: float, start: int, end: int) -> int:
    """The end of a breakaway window [start, end): BREAK_MARGIN rows after the recorded joint
    first moves (two rows in a row) in the `direction` of the motion that follows, else `end`."""
    going = direction * recorded[start:end] > STUCK_SPEED
    first = np.flatnonzero(going[:-1] & going[1:])
    return min(end, start + int(first[0]) + BREAK_MARGIN) if len(first) else end


def peak_windows(velocity: np.ndarray, window: int, recorded: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(starts, ends) of the windows after each start from rest or reversal (up to `window`
    rows, or the next event; with the `recorded` velocity, until just after the joint broke
    free), and of control windows of the same lengths half-way between events, where the joint
    runs: what a peak statistic shows there without any breakaway is its null."""
    events = start_events(velocity)
    events = events[events + window <= len(velocity)]
    following = np.r_[events[1:], len(velocity)]
    ends = np.minimum(events + window, following)
    if recorded is not None and np.any(recorded):
        ends = np.array([broken_free(recorded, np.sign(velocity[min(e + 2, len(velocity) - 1)]), e, end)
                         for e, end in zip(events, ends)], dtype=int)
    middles = (events + following) // 2
    keep = (np.abs(velocity[np.minimum(middles, len(velocity) - 1)]) > MOVING) & (following - middles >= 2)
    controls = middles[keep]
    return events, ends, controls, np.minimum(controls + (ends - events)[keep], following[keep])


def running_windows(residual: np.ndarray, starts: np.ndarray, ends: np.ndarray, noise: float) -> np.ndarray:
    """Per window [start, end): whether the `residual` (recording - a law's replay) swings about
    its own mean there by at most RUNNING_SWING times the channel's `noise` (the joint runs with
    the law; an offset of the running level is allowed, a transient is not)."""
    return np.array([float(np.std(residual[e:max(end, e + 2)])) <= RUNNING_SWING * noise
                     for e, end in zip(starts, ends)], dtype=bool)


def _scatter(null: np.ndarray, noise: float) -> float:
    """The scatter of a control window's peak: the windows' own spread, or with one window the
    channel's `noise`."""
    return float(np.std(null, ddof=1)) if len(null) > 1 else noise


def _smoothed(x: np.ndarray) -> np.ndarray:
    return running_mean(x, SMOOTH_ROWS)


def stiction_by_breakaway(chosen: ChannelFit | None, j: int, nominal, apply_fits,
                          q_cmd: np.ndarray, dt: float, q0: np.ndarray, dq_cmd: np.ndarray | None,
                          tau_real: np.ndarray, tau_nominal: np.ndarray, velocity: np.ndarray, moving: np.ndarray,
                          train: np.ndarray, noise: float, recorded: np.ndarray | None = None,
                          rivals: tuple[ChannelFit, ...] = ()) -> ChannelFit | None:
    """A Stribeck fit (judged by its breakaway peaks) where the recording's starts and reversals
    show stiction that `chosen` (a Coulomb/viscous fit, a Stribeck fit sized row by row, or None:
    the nominal) does not; else None.
    `j`: the joint (0-based).
    `tau_nominal`: the nominal replay's torque of the joint; `velocity`: the ideal-sensor
    replay's; `moving`: the rows where it moves (the running torque is judged there);
    `recorded`: the recording's velocity of the joint (where it breaks free), if it has one;
    `rivals`: other running laws (Coulomb/viscous) named beside `chosen` as equally good."""
    window = max(int(round(BREAKAWAY_S / dt)), 2)
    events, ends, controls, control_ends = peak_windows(velocity, window, recorded)
    in_train = train[np.maximum(ends - 1, events)] & train[events]
    in_held = ~train[events]
    control_train = train[np.maximum(control_ends - 1, controls)] & train[controls]
    if in_train.sum() < MIN_TRAIN_EVENTS or in_held.sum() < MIN_HELD_EVENTS or control_train.sum() < 2:
        return None
    last = int(np.flatnonzero(train).max()) + 1

    def replay(fit: ChannelFit | None, rows: int) -> np.ndarray | None:
        if fit is None:
            return tau_nominal[:rows]
        return replayed_torque(apply_fits(nominal, [fit]), q_cmd[:rows], dt, q0, j,
                               None if dq_cmd is None else dq_cmd[:rows])

    tau_chosen = replay(chosen, len(tau_real))
    if tau_chosen is None:
        return None
    real_peaks = event_peaks(tau_real, velocity, events, ends)
    excess = real_peaks - event_peaks(tau_chosen, velocity, events, ends)
    seen = excess[in_train]
    null = (event_peaks(tau_real, velocity, controls, control_ends)
            - event_peaks(tau_chosen, velocity, controls, control_ends))[control_train]
    # each side's spread at least what the other shows: two or three control windows can agree by chance
    spread = max(float(np.std(seen, ddof=1)), float(np.std(null, ddof=1)))
    se = spread * math.sqrt(1.0 / len(seen) + 1.0 / len(null))
    if not seen.mean() - null.mean() > EXCESS_Z * se:
        # large stiction disturbs the runs too: after a late breakaway the servo drives the joint
        # back onto its reference, and control windows there peak as high as the starts (60, 64 and
        # 35 N m beside 1.2 and 1.4 N m, 113 N m of stiction between point-to-point moves,
        # development seed 8101), so they measure the effect, not the noise on a maximum. The
        # null is then taken from the windows where the recording runs with the chosen law's replay
        # (its swing about the replay within RUNNING_SWING noise levels), where there are any: a single
        # such window's maximum scatters by about the channel's noise (_scatter); and only where the
        # starts' peaks stand LARGE_STICTION noise levels out
        clean = running_windows(tau_real - tau_chosen, controls, control_ends, noise)[control_train]
        if 0 < clean.sum() < len(clean) and float(np.median(seen)) > LARGE_STICTION * noise:
            # each side's own scatter (Welch): the starts' peaks differ by the move that follows them
            # (12.9-97.8 N m over five starts, 110 N m of stiction, test_stiction_disturbing_the_runs.py),
            # the running windows' by the noise on a maximum, taken as at least the channel's noise
            null = null[clean]
            se = math.sqrt(float(np.var(seen, ddof=1)) / len(seen) + max(_scatter(null, noise), noise) ** 2 / len(null))
    if not seen.mean() - null.mean() > EXCESS_Z * se:
        return None

    # fitted as the static level (where the recording breaks free) and the running level at the
    # joint's typical speed, which the peaks and the running torque pin down each on its own;
    # the decay speed follows from the two. Start: the chosen law's running level, and that
    # plus the peaks' excess.
    moving_train = moving & train
    speed = float(np.median(np.abs(velocity[moving_train]))) if moving_train.any() else 0.02
    running = float(np.median(np.sign(velocity[moving_train]) * chosen.prediction[moving_train])) \
        if chosen is not None and moving_train.any() else 0.0
    running = max(running, 0.1 * noise)
    level0 = running + max(float(np.median(seen)) - float(null.mean()), EXCESS_Z * se)
    train_events, train_ends = events[in_train], ends[in_train]
    real_train = real_peaks[in_train] - null.mean()
    rows = moving_train[:last]

    def decay(level: float, run: float) -> float:
        ratio = level / run if run > 0 else math.inf
        return float(np.clip(speed / math.sqrt(math.log(max(ratio, 1.0001))), *STRIBECK_VELOCITY_RANGE))

    def trial(log_level: float, log_running: float) -> ChannelFit:
        level = math.exp(log_level)
        return ChannelFit(("stribeck",), "tau", j, np.array([level]), np.zeros(1),
                          ("stribeck_friction",), (decay(level, math.exp(log_running)),),
                          math.nan, math.nan, 0.0, 0.0, 1.0, 1, n_train=int(rows.sum()), n_params=2)

    def error(x: np.ndarray) -> float:
        tau = replay(trial(float(x[0]), float(x[1])), last)
        if tau is None:
            return math.inf
        peaks = event_peaks(tau, velocity, train_events, train_ends)
        run = _smoothed(tau_real[:last] - tau)[rows]
        return float(np.mean((real_train - peaks) ** 2) + np.mean(run ** 2))

    start = np.array([math.log(level0), math.log(running)])
    simplex = np.array([start, start + [0.3, 0.0], start + [0.0, 0.3]])
    best = minimize(error, start, method="Nelder-Mead",
                    options={"initial_simplex": simplex, "xatol": 0.02, "fatol": 1e-3 * noise ** 2,
                             "maxfev": MAX_REPLAYS})
    if not np.isfinite(best.fun):
        return None
    fit = trial(float(best.x[0]), float(best.x[1]))
    tau_fit = replay(fit, len(tau_real))
    if tau_fit is None:
        return None
    fit_excess = real_peaks - null.mean() - event_peaks(tau_fit, velocity, events, ends)
    held_before = float(np.sqrt(np.mean((excess[in_held] - null.mean()) ** 2)))
    held_after = float(np.sqrt(np.mean(fit_excess[in_held] ** 2)))
    held_rows = moving & ~train
    run_before = float(np.sqrt(np.mean(_smoothed(tau_real - tau_chosen)[held_rows] ** 2)))
    run_after = float(np.sqrt(np.mean(_smoothed(tau_real - tau_fit)[held_rows] ** 2)))
    # the held-out peaks must stand above the chosen law's by more than EXCESS_Z standard errors
    # of their mean; a peak's scatter: the training events' about the fit, or the control
    # windows', the larger
    spread = max(float(np.std(fit_excess[in_train], ddof=1)), _scatter(null, noise))
    held_excess = float(np.mean(excess[in_held] - null.mean()))
    # ... and above every running law named beside the chosen one: where the first
    # choice is viscous friction with Coulomb beside it, Coulomb friction's replay meets the
    # peaks at reversals that the viscous one misses (26 N m of Coulomb friction at a 0.0085
    # rad/s ramp was refitted as "stiction" 26.7 N m fading above 0.049 rad/s, development test)
    for rival in rivals:
        tau_rival = replay(rival, len(tau_real))
        if tau_rival is None:
            continue
        over = real_peaks - event_peaks(tau_rival, velocity, events, ends) - null.mean()
        held_excess = min(held_excess, float(np.mean(over[in_held])))
    # and the fit's own stiction (its static level above its running level at the joint's typical
    # speed) at least MIN_STICTION_SHARE of its level: the rival above was a linear fit 1 % low,
    # and its few, consistent peaks (0.3 N m scatter) left 0.5 N m of "stiction" significant, a
    # law 3 % above its running level. No multiple of the channel's noise: a joint's own chatter
    # (6 N m on the test bed's joint 3 alone) rejected 9 N m of stiction that way
    share = 1.0 - math.exp(-(speed / float(fit.shape[0])) ** 2)
    if not (held_excess > EXCESS_Z * spread / math.sqrt(in_held.sum()) and held_after < held_before
            and run_after <= RUNNING_RATIO * run_before and share >= MIN_STICTION_SHARE):
        return None
    # the level's standard error: the training events' scatter about the fitted peaks (each
    # event one independent look at the static level) and the control windows' (the noise
    # taken off the peaks), through how far the peaks move with the level (less than one to one)
    resid = fit_excess[in_train]
    peak_se = math.hypot(float(np.std(resid, ddof=1)) / math.sqrt(len(resid)),
                         _scatter(null, noise) / math.sqrt(len(null)))
    higher = replay(trial(float(best.x[0]) + 0.1, float(best.x[1])), last)
    lower = replay(trial(float(best.x[0]) - 0.1, float(best.x[1])), last)
    if higher is None or lower is None:
        return None
    slope = float(np.mean(event_peaks(higher, velocity, train_events, train_ends)
                          - event_peaks(lower, velocity, train_events, train_ends))) / (0.2 * float(fit.coef[0]))
    stderr = peak_se / max(slope, 0.1)
    fit.stderr = np.array([stderr])
    fit.prediction = tau_fit - tau_nominal
    fit.judged_by = "breakaway"
    fit.rms_heldout_before, fit.rms_heldout_after = held_before, held_after
    fit.p_value, fit.n_params = 0.0, 2
    return fit
