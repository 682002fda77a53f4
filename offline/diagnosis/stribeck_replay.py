"""Stiction on slow motion with reversals, fitted and judged by replays of the whole joint.

On a slow ramp back and forth (or any slow motion that reverses) a Stribeck law and the
Coulomb law of its running level run at the same torque; their breakaway peaks differ by the
stiction's share of the level only (8 % of 23.5 N m at a 0.0072 rad/s ramp, a 0.025 rad/s
decay: 1.9 N m), and a slow joint sticks and slips along the whole run, so control windows
mid-run peak nearly as high as the reversals (stick_slip.py's screen saw 0.5 of the 1.9 N m,
development seed 7002). What differs beyond noise is the reversal itself: a joint that
must first reach the static level sticks longer and its torque swings through the reversal
later, and a replay of the true law follows that swing row by row where the Coulomb replay
misses it by up to 9 N m (the first 0.5 s after each held-out reversal: 3.5 N m RMS under the
Coulomb law, 0.9 N m under the true one).

So a Stribeck law (its static level and its running level at the joint's typical speed, the
decay speed following from the two, as stick_slip fits it) is fitted by replays of the joint on
the training rows just after each start and reversal, and so is Coulomb friction. The
Stribeck law replaces the chosen law (a running law, or a Stribeck law sized row by row) only
where its replay lowers the held-out torque RMS by MIN_CONFIRMED_REDUCTION (the share the
diagnosis needs to confirm any finding) against both the chosen law's replay and the Coulomb
replay; failing that, a chosen row-by-row Stribeck law whose replay the Coulomb one beats by
that share gives way to it. Every replay starts away from the recorded start, at several
places within the resolver quantum (as separable.py does at one): from the recorded start the
true plant alone replays the servo's chatter in phase, which no model of a real arm could
use, and a law that wins from one start only won by the chatter's phase.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from spacearm.offline.diagnosis.breakaway import start_events
from spacearm.offline.diagnosis.direct_sim import replayed_torque
from spacearm.offline.diagnosis.fitting import ChannelFit
from spacearm.offline.diagnosis.honesty import MIN_CONFIRMED_REDUCTION
from spacearm.offline.diagnosis.running_mean import running_mean

MIN_EVENTS = 4              # reversals and starts, training and held-out rows together
MIN_HELD_EVENTS = 2
MAX_REPLAYS = 30
# decay speed / the joint's typical speed, the grid the fit starts from (the static level at the
# first is e = 2.7 times the running one, at the last 1.6 % above it)
DECAY_GRID = (1.0, 1.4, 2.0, 2.8, 4.0, 8.0)
SMOOTH_ROWS = 5             # 0.1 s at 50 Hz: the reversal's swing kept, the chatter's row-to-row scatter not
# where within the resolver quantum the judging replays start (quanta from the recorded start)
START_OFFSETS = (0.25, 0.5, 0.75)
SWING_S = 1.0               # s after a start or reversal: the swing the fit is made on
DECAY_RANGE = (0.002, 0.1)  # rad/s (m/s), as stick_slip.STRIBECK_VELOCITY_RANGE
SLOW = 0.05                 # rad/s (m/s): only joints whose typical speed is below this (a stiction of decay
                            # speed up to DECAY_RANGE's end would fade before a faster one's running level)


def _smoothed(x: np.ndarray) -> np.ndarray:
    return running_mean(x, SMOOTH_ROWS)


def stribeck_by_replay(chosen: ChannelFit, j: int, nominal, apply_fits, q_cmd: np.ndarray, dt: float,
                       q0: np.ndarray, dq_cmd: np.ndarray | None, tau_real: np.ndarray, velocity: np.ndarray,
                       moving: np.ndarray, train: np.ndarray) -> ChannelFit | None:
    """A Stribeck fit of joint `j` (0-based) that replaces `chosen` (a Coulomb, viscous or
    Stribeck fit sized row by row)
    where its replay explains the held-out torque better by MIN_CONFIRMED_REDUCTION; else None.
    `velocity`: the ideal-sensor nominal replay's velocity of the joint; `moving`: its moving rows."""
    events = start_events(velocity)
    if len(events) < MIN_EVENTS or (~train[events]).sum() < MIN_HELD_EVENTS or not (moving & train).any():
        return None
    speed = float(np.median(np.abs(velocity[moving & train])))
    if speed >= SLOW:
        return None
    quantum = nominal.joint_params(j).position_quantum
    rows = len(tau_real)
    last = int(np.flatnonzero(train).max()) + 1

    def replay(fit: ChannelFit, upto: int = rows, offset: float = 0.5) -> np.ndarray | None:
        start = q0.copy()
        start[j] += offset * quantum
        return replayed_torque(apply_fits(nominal, [fit]), q_cmd[:upto], dt, start, j,
                               None if dq_cmd is None else dq_cmd[:upto])

    running = float(np.median(np.sign(velocity[moving & train]) * chosen.prediction[moving & train]))
    if running <= 0.0:
        return None

    def trial(x: np.ndarray) -> ChannelFit:
        level, run = math.exp(float(x[0])), math.exp(float(x[1]))
        return ChannelFit(("stribeck",), "tau", j, np.array([level]), np.zeros(1), ("stribeck_friction",),
                          (fading_speed(speed, level / run if run > 0 else math.inf),), math.nan, math.nan,
                          0.0, 0.0, 1.0, 1, n_train=int(train.sum()), n_params=2)

    # the training loss over the rows just after each start and reversal, where the laws differ
    after_event = np.zeros(rows, bool)
    for e in events:
        after_event[e:e + max(int(round(SWING_S / dt)), 2)] = True
    fit_rows = (after_event & train)[:last]
    losses: dict[tuple[float, float], float] = {}
    errors: dict[tuple[float, float], np.ndarray] = {}     # per fitted row, for the jackknife below

    def loss(x: np.ndarray) -> float:
        key = (round(float(x[0]), 6), round(float(x[1]), 6))
        if key not in losses:
            tau = replay(trial(x), last)
            if tau is None:
                losses[key] = math.inf
            else:
                errors[key] = _smoothed(tau_real[:last] - tau)[fit_rows] ** 2
                losses[key] = float(np.mean(errors[key]))
        return losses[key]

    # the decay speed on a grid first (the level set by the chosen law's running level there):
    # the loss is flat along the level-decay trade-off, and a simplex from one start settled on
    # the running level itself on a development case
    grid = [np.array([math.log(running) + (1.0 / r) ** 2, math.log(running)]) for r in DECAY_GRID]
    x0 = min(grid, key=loss)
    best = minimize(loss, x0, method="Nelder-Mead",
                    options={"initial_simplex": np.array([x0, x0 + [0.05, 0.0], x0 + [0.0, 0.05]]),
                             "xatol": 0.005, "fatol": 1e-4 * running ** 2, "maxfev": MAX_REPLAYS})
    fit = trial(best.x) if np.isfinite(best.fun) and best.x[0] > best.x[1] else None    # else no stiction
    held = ~train
    rms = lambda tau: float(np.sqrt(np.mean((tau_real - tau)[held] ** 2)))
    coulomb_errors: dict[tuple[float, float], np.ndarray] = {}
    coulomb = _coulomb_by_replay(running, j, replay, lambda tau: _smoothed(tau_real[:last] - tau)[fit_rows] ** 2,
                                 last, coulomb_errors)
    # judged from every start within the resolver quantum against the chosen law's replay and
    # Coulomb friction fitted by replays on the same rows: 19.5 N m of Coulomb friction on a slow
    # ramp was named stiction fading above 0.079 rad/s (2 % above its running level) at 5 % below
    # the chosen law's replay from half a quantum away, and the row-by-row Stribeck law chosen
    # there (41 N m) replayed 6 times worse than Coulomb friction (test_stribeck_reversal_swing.py)
    scores = []
    for offset in START_OFFSETS:
        laws = [replay(law, offset=offset) if law is not None else None for law in (fit, chosen, coulomb)]
        if laws[1] is None or laws[2] is None:
            return None
        scores.append([rms(x) if x is not None else math.inf for x in laws])
    scores = np.array(scores)
    better = lambda a, b: bool(np.all(scores[:, a] <= (1.0 - MIN_CONFIRMED_REDUCTION) * scores[:, b]))
    if fit is not None and better(0, 1) and better(0, 2):
        winner, errors_of = fit, errors
    elif "stribeck" in chosen.effects and better(2, 1):
        winner, errors_of = coulomb, coulomb_errors
    else:
        return None
    tau_nominal = replay(ChannelFit(("stribeck",), "tau", j, np.zeros(1), np.zeros(1), ("stribeck_friction",),
                                    (nominal.joint_params(j).stribeck_velocity,), 0.0, 0.0, 0.0, 0.0, 1.0, 1)) \
        if nominal.joint_params(j).stribeck_friction == 0.0 else None
    tau_fit, tau_chosen = replay(winner), replay(chosen)
    if tau_nominal is None or tau_fit is None or tau_chosen is None:
        return None             # a nominal with stiction of its own: not this law's case
    # the level's standard error: the spread of the best level over the replays made, each
    # training reversal (each one look at the level) left out in turn; the training loss's
    # curvature said +-0.6-1.5 % where the fits missed by 3-4 % (development seed 7002)
    rel = _jackknife_spread(errors_of, np.flatnonzero(fit_rows), events[train[events]])
    # ... and at least what the loss's curvature in the log level says, each training reversal
    # counted as one look (the jackknife's picks can all agree among a few replays)
    h = 0.05
    def scaled(f: float) -> float:
        tau = replay(ChannelFit(winner.effects, "tau", j, winner.coef * math.exp(f), np.zeros(1), winner.columns,
                                winner.shape, math.nan, math.nan, 0.0, 0.0, 1.0, 1), last)
        return math.inf if tau is None else float(np.mean(_smoothed(tau_real[:last] - tau)[fit_rows] ** 2))

    mid = scaled(0.0)
    curv = (scaled(h) - 2 * mid + scaled(-h)) / h ** 2
    rel = max(rel, math.sqrt(2 * mid / curv / train[events].sum()) if 0 < curv < math.inf else math.inf)
    winner.stderr = np.array([float(winner.coef[0]) * rel])
    winner.prediction = tau_fit - tau_chosen + chosen.prediction
    winner.rms_heldout_before, winner.rms_heldout_after = rms(tau_nominal), rms(tau_fit)
    winner.sse_train, winner.p_value, winner.n_train = float(np.sum(errors_of[min(errors_of, key=lambda k: float(
        np.sum(errors_of[k])))])), 0.0, int(fit_rows.sum())
    return winner

def _jackknife_spread(errors: dict[tuple[float, float], np.ndarray], rows: np.ndarray, events: np.ndarray) -> float:
    """Jackknife standard error of the best log level among the replays made (key: log level,
    log running level; value: squared error on `rows`), each start or reversal of `events`
    (with the rows up to the next one) left out in turn."""
    if len(events) < 3 or len(errors) < 3:
        return math.inf
    keys = list(errors)
    table = np.array([errors[k] for k in keys])
    owner = np.searchsorted(events, rows, side="right") - 1
    picks = []
    for i in range(len(events)):
        keep = owner != i
        picks.append(keys[int(np.argmin(table[:, keep].sum(axis=1)))][0])
    picks = np.array(picks)
    m = len(picks)
    return float(math.sqrt((m - 1) / m * np.sum((picks - picks.mean()) ** 2)))


def fading_speed(speed: float, ratio: float) -> float:
    """The Stribeck decay speed at which stiction `ratio` times the running level has fallen to
    the running level at `speed` (within DECAY_RANGE)."""
    return float(np.clip(speed / math.sqrt(math.log(max(ratio, 1.0001))), *DECAY_RANGE))


def coulomb_law(j: int, level: float) -> ChannelFit:
    """Coulomb friction `level` on joint `j`, as a fit to replay (not sized by rows)."""
    return ChannelFit(("coulomb",), "tau", j, np.array([level]), np.zeros(1), ("coulomb_friction",), (math.nan,),
                      math.nan, math.nan, 0.0, 0.0, 1.0, 1, n_params=1)


def _coulomb_by_replay(running: float, j: int, replay, errors_of, last: int,
                       errors: dict[tuple[float, float], np.ndarray]) -> ChannelFit:
    """The Coulomb friction of joint `j` (within 30 % of `running`) whose replay's first `last`
    rows have the least mean of `errors_of(torque)` (per row; each kept in `errors` by log level)."""
    law = lambda log_level: coulomb_law(j, math.exp(log_level))

    def cost(log_level: float) -> float:
        tau = replay(law(log_level), last)
        if tau is None:
            return math.inf
        errors[(round(float(log_level), 6), 0.0)] = errors_of(tau)
        return float(np.mean(errors[(round(float(log_level), 6), 0.0)]))

    best = minimize_scalar(cost, bounds=(math.log(0.7 * running), math.log(1.3 * running)), method="bounded",
                           options={"xatol": 0.005, "maxiter": 12})
    return law(float(best.x))
