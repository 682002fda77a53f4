"""The size of a fitted torque effect refined by replaying the joint with it.

The linear candidates predict the disturbance torque from the nominal motion, but the real
joint does not follow the nominal motion exactly: it sticks at reversals and at rest, and
lags where the drive has to push. The plant with the effect reproduces that, so one scale
factor on the effect's size is searched by single-joint replays of the training rows
(bounded, on a log scale), judged by the torque residual where the joint moves. With the
size right, the replay even reproduces the resolver chatter of the recording, which is
what lifts the held-out match above the noise floor.

Stiction (Stribeck) is left at its linear estimate: the joint sticks and slips at random
below the decay speed, and the replay's residual was no better a guide to its size than the
linear fit (tried: the size moved toward the truth in one case of three, the held-out
match got worse).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar

from spacearm.offline.diagnosis.direct_sim import simulate
from spacearm.offline.diagnosis.fitting import ChannelFit
from spacearm.firmware_sim.plant import PlantConfig

# scale range searched around the linear estimate, per effect
SCALE_RANGE = {"coulomb": (0.7, 1.4), "viscous": (0.7, 1.4), "gravity_load": (0.7, 1.4)}
SIZE_COLUMNS = ("coulomb_friction", "viscous_friction", "load_cos", "load_sin")


def refine_size(fit: ChannelFit, nominal: PlantConfig, q_cmd: np.ndarray, dt: float, q0: np.ndarray,
                tau_real: np.ndarray, rows: np.ndarray, apply) -> ChannelFit:
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
                sim = simulate(apply(nominal, [fit]), q_cmd[:last], dt, q0=q0, joints=[j])
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
