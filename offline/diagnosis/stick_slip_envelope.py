"""Stiction told by the stick-slip it drives on slow running motion, judged by its envelope.

Friction that falls with speed (a Stribeck law whose decay speed is near the running speed)
is negative damping: the servo holding a slow joint on its ramp oscillates, sticking and
slipping all along the run, not only at reversals. Coulomb and viscous friction are passive
and drive no such oscillation. The recorded torque then swings far beyond the nominal's
chatter (11 N m RMS about its 1 s mean against 4.6 N m for the replay of the Coulomb law of
the same running level, 27 N m of stiction fading above 0.013 rad/s at a 0.011 rad/s ramp,
development seed 5402), while the running level, which is all the row-by-row fits see, is
the same for all three laws. Row by row the stick-slip is no guide: its phase is set by
sub-quantum resolver states no recording gives, and the true law's own replay scored a
higher RMS (12.8 N m) than the Coulomb law's (11.2). Its envelope is reproducible: the true
law's replay matched the recorded swing's envelope to 1.0 N m, the Coulomb replay to 7.2.

So the static level is fitted (the running level held, which sets the decay speed, as in
stribeck_replay.py) by replays of the joint, on the training rows' envelope of the torque's
swing about its 1 s running mean; and the law is kept only where its replay's envelope
error on the held-out rows is below both the chosen law's and the Coulomb law's by
MIN_CONFIRMED_REDUCTION from every start within the resolver quantum.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar

from spacearm.offline.diagnosis.breakaway import start_events
from spacearm.offline.diagnosis.direct_sim import replayed_torque
from spacearm.offline.diagnosis.fitting import ChannelFit
from spacearm.offline.diagnosis.gear_effects import envelope
from spacearm.offline.diagnosis.honesty import MIN_CONFIRMED_REDUCTION
from spacearm.offline.diagnosis.running_mean import running_mean
from spacearm.offline.diagnosis.stribeck_replay import (MIN_EVENTS, MIN_HELD_EVENTS, SLOW, START_OFFSETS,
                                                        _jackknife_spread, coulomb_law, fading_speed)

SWING_S = 1.0               # s: the running mean the swing is taken about (a slip cycle is shorter)
# static / running level tried: from just above the running level (no stick-slip) to where the
# stiction is six times it; the loss has a step where stick-slip sets in, so a grid comes first
RATIOS = (1.1, 1.25, 1.5, 1.75, 2.0, 2.5, 3.0, 4.0, 6.0)
REFINE_EVALS = 8
NULL_MARGIN = 2.0           # as analysis.NULL_MARGIN: a null draw scatters up to about 1.7x


def swing(tau: np.ndarray, rows: int) -> np.ndarray:
    """The torque's swing about its running mean over `rows` rows."""
    return tau - running_mean(tau, rows)


def stiction_by_swing(chosen: ChannelFit, j: int, nominal, apply_fits, q_cmd: np.ndarray, dt: float,
                      q0: np.ndarray, dq_cmd: np.ndarray | None, tau_real: np.ndarray, velocity: np.ndarray,
                      moving: np.ndarray, train: np.ndarray) -> ChannelFit | None:
    """A Stribeck fit of joint `j` (0-based), judged by the envelope of the torque's swing,
    that replaces `chosen` (a running law sized row by row); else None. `velocity`: the
    ideal-sensor nominal replay's velocity; `moving`: its moving rows."""
    events = start_events(velocity)
    if len(events) < MIN_EVENTS or (~train[events]).sum() < MIN_HELD_EVENTS or not (moving & train).any():
        return None
    speed = float(np.median(np.abs(velocity[moving & train])))
    running = float(np.median(np.sign(velocity[moving & train]) * chosen.prediction[moving & train]))
    if speed >= SLOW or running <= 0.0 or nominal.joint_params(j).stribeck_friction != 0.0:
        return None
    quantum = nominal.joint_params(j).position_quantum
    window = max(int(round(SWING_S / dt)), 3)
    real = envelope(swing(tau_real, window))

    def replay(fit: ChannelFit, offset: float = 0.5) -> np.ndarray | None:
        start = q0.copy()
        start[j] += offset * quantum
        return replayed_torque(apply_fits(nominal, [fit]), q_cmd, dt, start, j, dq_cmd)

    def errors(tau: np.ndarray | None, rows: np.ndarray) -> np.ndarray:
        if tau is None:
            return np.full(int(rows.sum()), np.inf)
        return (real - envelope(swing(tau, window)))[rows] ** 2

    fit_rows, held = moving & train, moving & ~train
    if fit_rows.sum() < 10 * window or held.sum() < 2 * window:
        return None
    kept: dict[tuple[float, float], np.ndarray] = {}
    kept_held: dict[tuple[float, float], float] = {}

    def loss(log_ratio: float) -> float:
        key = (round(math.log(running) + log_ratio, 6), round(math.log(running), 6))
        if key not in kept:
            tau = replay(_law(j, running, math.exp(log_ratio), speed, train))
            kept[key], kept_held[key] = errors(tau, fit_rows), float(np.mean(errors(tau, held)))
        return float(np.mean(kept[key]))

    grid = [math.log(r) for r in RATIOS]
    at = int(np.argmin([loss(g) for g in grid]))
    low, high = grid[max(at - 1, 0)], grid[min(at + 1, len(grid) - 1)]
    best = minimize_scalar(loss, bounds=(low, high), method="bounded", options={"xatol": 0.01,
                                                                               "maxiter": REFINE_EVALS})
    log_ratio = float(best.x) if best.fun <= loss(grid[at]) else grid[at]
    fit = _law(j, running, math.exp(log_ratio), speed, train)
    coulomb = coulomb_law(j, running)
    rms = lambda tau: float(np.sqrt(np.mean(errors(tau, held))))
    replays = [[replay(law, offset) for law in (fit, chosen, coulomb)] for offset in START_OFFSETS]
    if any(tau is None for row in replays for tau in row):
        return None
    scores = np.array([[rms(tau) for tau in row] for row in replays])
    # what the chosen law's swing envelope differs by between two equally valid starts: a gain
    # no larger is no evidence (1806 N m s/rad of viscous friction was named stiction at 5 %
    # below its own replay's envelope error, test_stribeck_reversal_swing.py)
    envelope_of = lambda tau: envelope(swing(tau, window))[held]
    null = float(np.sqrt(np.mean((envelope_of(replays[0][1]) - envelope_of(replays[-1][1])) ** 2)))
    limit = np.minimum((1.0 - MIN_CONFIRMED_REDUCTION) * np.minimum(scores[:, 1], scores[:, 2]),
                       np.minimum(scores[:, 1], scores[:, 2]) - NULL_MARGIN * null)
    if not np.all(np.isfinite(scores)) or not np.all(scores[:, 0] <= limit):
        return None
    tau_fit, tau_chosen, tau_nominal = replay(fit), replay(chosen), replay(coulomb_law(j, 0.0))
    if tau_fit is None or tau_chosen is None or tau_nominal is None:
        return None
    # the level's standard error: the spread of the best level among the replays made, each
    # training start or reversal (with the rows up to the next) left out in turn
    rel = _jackknife_spread(kept, np.flatnonzero(fit_rows), events[train[events]])
    # ... and at least what the loss's curvature in the log level says, each training reversal
    # one look (the jackknife's picks can all agree among the few levels replayed)
    h = 0.05
    mid, up, down = loss(log_ratio), loss(log_ratio + h), loss(log_ratio - h)
    curv = (up - 2 * mid + down) / h ** 2
    looks = int(train[events].sum())
    rel = max(rel, math.sqrt(2 * mid / curv / looks) if 0 < curv < math.inf else math.inf)
    # ... and at least the model's own error: the level the held-out rows' swing calls for among
    # the replays made differs from the training rows' by it and by two samplings (one law fitted
    # to stick-slip it reproduces only in envelope: 29.5 +- 1.2 N m stated where 27.1 was true)
    held_best = min(kept_held, key=kept_held.get)[0]
    rel = max(rel, abs(held_best - (math.log(running) + log_ratio)) / math.sqrt(2.0))
    if not rel < 0.5:
        return None             # a size not known to half its value is no finding (honesty.uncertain)
    fit.stderr = np.array([float(fit.coef[0]) * rel])
    fit.judged_by = "envelope"
    fit.prediction = tau_fit - tau_chosen + chosen.prediction
    fit.rms_heldout_before, fit.rms_heldout_after = rms(tau_nominal), rms(tau_fit)
    fit.sse_train, fit.p_value, fit.n_train = float(np.sum(kept[min(kept, key=lambda k: float(
        np.sum(kept[k])))])), 0.0, int(fit_rows.sum())
    return fit


def _law(j: int, running: float, ratio: float, speed: float, train: np.ndarray) -> ChannelFit:
    """Stiction `ratio` times the running level, fading so that it is `running` at `speed`."""
    return ChannelFit(("stribeck",), "tau", j, np.array([running * ratio]), np.zeros(1), ("stribeck_friction",),
                      (fading_speed(speed, ratio),), math.nan, math.nan, 0.0, 0.0, 1.0, 1, n_train=int(train.sum()), n_params=2)
