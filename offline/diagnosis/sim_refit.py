"""The size of a fitted torque effect refined by replaying the joint with it.

The linear candidates predict the disturbance torque from the nominal motion, but the real
joint does not follow the nominal motion exactly: it sticks at reversals and at rest, and
lags where the drive has to push. The plant with the effect reproduces that, so one scale
factor on the effect's size is searched by single-joint replays of the training rows
(bounded, on a log scale), judged by the torque residual where the joint moves. With the
size right, the replay even reproduces the resolver chatter of the recording, which is
what lifts the held-out match above the noise floor.

Stiction (Stribeck) needs both its level and its decay speed searched together
(`refine_stiction`): the joint sticks and slips below the decay speed, and a larger level
with a slower decay gives the linear fit nearly the same torque impulse, so the linear
estimate of the level came out 15-25 % low. A replay of the joint with both reproduces
when it breaks free, and that is sharp in the pair (judged on every training row: the
rows where the joint sticks carry the information; the moving rows alone did not).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from spacearm.offline.diagnosis.direct_sim import simulate
from spacearm.offline.diagnosis.fitting import ChannelFit
from spacearm.firmware_sim.plant import PlantConfig

# scale range searched around the linear estimate, per effect
SCALE_RANGE = {"coulomb": (0.7, 1.4), "viscous": (0.7, 1.4), "gravity_load": (0.7, 1.4)}
SIZE_COLUMNS = ("coulomb_friction", "viscous_friction", "load_cos", "load_sin", "load_force")


def refine_size(fit: ChannelFit, nominal: PlantConfig, q_cmd: np.ndarray, dt: float, q0: np.ndarray,
                tau_real: np.ndarray, rows: np.ndarray, apply, dq_cmd: np.ndarray | None = None) -> ChannelFit:
    """The fit with its size columns scaled by the factor whose replay matches the recorded
    torque best on `rows` (boolean, within the leading training part). `apply(nominal, fits)`
    builds the plant with a fit switched on."""
    if len(fit.effects) != 1 or fit.effects[0] not in SCALE_RANGE:
        return fit
    lo, hi = SCALE_RANGE[fit.effects[0]]
    last = int(np.flatnonzero(rows).max()) + 1 if rows.any() else 0
    if last < 10:
        return fit
    j = fit.index
    size = np.array([c in SIZE_COLUMNS for c in fit.columns])
    base = fit.coef.copy()

    def error(log_scale: float) -> float:
        fit.coef = np.where(size, base * math.exp(log_scale), base)
        try:
            with np.errstate(all="raise"):
                sim = simulate(apply(nominal, [fit]), q_cmd[:last], dt, q0=q0, joints=[j],
                               dq_cmd=None if dq_cmd is None else dq_cmd[:last], wrench=False)
            r = (tau_real[:last] - sim.tau[:, 0])[rows[:last]]
        except (OverflowError, FloatingPointError, ValueError):
            return math.inf
        return float(np.mean(r ** 2)) if np.all(np.isfinite(r)) else math.inf

    start = error(0.0)
    best = minimize_scalar(error, bounds=(math.log(lo), math.log(hi)), method="bounded",
                           options={"xatol": 0.01, "maxiter": 10})
    scale = math.exp(best.x) if best.fun < start else 1.0
    fit.coef = np.where(size, base * scale, base)
    fit.stderr = np.where(size, fit.stderr * scale, fit.stderr)
    return fit


STICTION_START_STEP = 0.15              # log units: the search's first simplex around the linear fit


def refine_stiction(fit: ChannelFit, nominal: PlantConfig, q_cmd: np.ndarray, dt: float, q0: np.ndarray,
                    tau_real: np.ndarray, train: np.ndarray, apply, dq_cmd: np.ndarray | None = None) -> ChannelFit:
    """A Stribeck fit with its level and decay speed found together by replays of the joint
    on the training rows (Nelder-Mead on the logs, from the linear estimate). Its standard
    error is the linear fit's (block jackknife, fitting.py), scaled with the level. Left as it
    is when no replay beats the linear estimate's."""
    if fit.effects != ("stribeck",) or not train.any():
        return fit
    last = int(np.flatnonzero(train).max()) + 1
    j = fit.index
    level0, decay0 = float(fit.coef[0]), float(fit.shape[0])
    if not (level0 > 0 and decay0 > 0):
        return fit
    cache: dict[tuple[float, float], np.ndarray | None] = {}

    def replay_tau(log_level: float, log_decay: float) -> np.ndarray | None:
        key = (round(log_level, 6), round(log_decay, 6))
        if key not in cache:
            trial = _with(fit, math.exp(log_level), math.exp(log_decay))
            try:
                with np.errstate(all="raise"):
                    sim = simulate(apply(nominal, [trial]), q_cmd[:last], dt, q0=q0, joints=[j],
                                   dq_cmd=None if dq_cmd is None else dq_cmd[:last], wrench=False)
                cache[key] = sim.tau[:, 0] if np.all(np.isfinite(sim.tau)) else None
            except (OverflowError, FloatingPointError, ValueError):
                cache[key] = None
        return cache[key]

    rows = train[:last]

    def error(x: np.ndarray) -> float:
        tau = replay_tau(float(x[0]), float(x[1]))
        return math.inf if tau is None else float(np.mean((tau_real[:last] - tau)[rows] ** 2))

    start = np.array([math.log(level0), math.log(decay0)])
    linear = error(start)
    simplex = np.array([start, start + [STICTION_START_STEP, 0.0], start + [0.0, STICTION_START_STEP]])
    best = minimize(error, start, method="Nelder-Mead",
                    options={"initial_simplex": simplex, "xatol": 0.01, "fatol": 1e-4 * max(linear, 1e-12),
                             "maxfev": 30})
    if not best.fun < linear:
        return fit
    level, decay = math.exp(best.x[0]), math.exp(best.x[1])
    refined = _with(fit, level, decay)
    refined.stderr = fit.stderr * level / level0
    return refined


def _with(fit: ChannelFit, level: float, decay: float) -> ChannelFit:
    return replace(fit, coef=np.array([level]), shape=(decay,), stderr=fit.stderr.copy())
