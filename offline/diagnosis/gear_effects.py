"""Gear effects found by simulation: backlash and joint elasticity.

With the resolver on the link and the motor inside the servo loop, play or a soft gear makes
the drive hunt: a torque ripple the nominal simulation does not have, whose phase is not
reproducible sample by sample. So these candidates are compared by their 0.5 s RMS envelope
(recording residual vs single-joint simulation with the effect plus noise), and the size is
found by a bounded one-dimensional search on a log scale (scipy).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar

from spacearm.offline.diagnosis.direct_sim import simulate
from spacearm.offline.diagnosis.fitting import ChannelFit, block_jackknife_stderr
from spacearm.offline.diagnosis.running_mean import running_mean
from spacearm.firmware_sim.plant import PlantConfig

# Play below about three resolver quanta (25 arcsec each) hunts no differently from the
# resolver chatter a stick-slip joint makes, so the search starts there.
# Stiffer than 1e6 N m/rad the explicit two-mass step (1 ms .. 2 ms) is no longer stable.
GEAR_EFFECTS = {"backlash": ("backlash", 3.0e-4, 2e-2), "elasticity": ("joint_stiffness", 3e3, 1e6)}
WINDOW = 25
MIN_HELDOUT_REDUCTION = 0.5
DIVERGED = 1e300            # loss of a size whose simulation diverges
JACKKNIFE_GRID = np.linspace(-0.3, 0.3, 13)   # log sizes around the fit simulated for the jackknife


def envelope(x: np.ndarray, window: int = WINDOW) -> np.ndarray:
    return np.sqrt(running_mean(x ** 2, window))


def fit_gear_effect(effect: str, nominal: PlantConfig, q_cmd: np.ndarray, dt: float, q0: np.ndarray,
                    base_tau: np.ndarray, residual: np.ndarray, noise: float, j: int,
                    train: np.ndarray, base_q: np.ndarray | None = None,
                    q_residual: np.ndarray | None = None, dq_cmd: np.ndarray | None = None) -> ChannelFit:
    """With `base_q` and `q_residual` (the ideal-sensor replay's position and the recording's
    position minus it) the size is found on the position envelope: once the drive hunts, its
    torque ripple is set by the drive's own limits and hardly grows with the play (the loss
    over the size is flat and ragged), while the link's position wanders through the play, so
    its envelope grows steadily with the size. The torque envelope still decides whether the
    effect is there and what it explains."""
    key, lo, hi = GEAR_EFFECTS[effect]
    joints = [nominal.joint_params(i) for i in range(q_cmd.shape[1])]
    env_real = envelope(residual)
    by_position = base_q is not None and q_residual is not None
    if by_position:
        q_noise = joints[j].position_quantum / math.sqrt(12.0)
        env_q_real = envelope(q_residual)
    sims: dict[float, object] = {}

    def simulated(log_value: float):
        if log_value not in sims:
            p = joints[j].model_copy(update={key: float(math.exp(log_value)), "resolver_arcsec": 0.0,
                                            "encoder_quantum": 0.0, "torque_noise": 0.0})
            js = list(joints)
            js[j] = p
            try:
                # a light joint with a stiff gear or wide play can make the explicit step diverge
                with np.errstate(all="raise"):
                    sims[log_value] = simulate(nominal.model_copy(update={"joints": js}), q_cmd, dt, q0=q0, joints=[j],
                                                 dq_cmd=dq_cmd, wrench=False)
            except (OverflowError, FloatingPointError, ValueError):
                sims[log_value] = None
        return sims[log_value]

    def predicted_on(channel: str, base: np.ndarray, floor: float):
        def predicted(log_value: float) -> np.ndarray | None:
            sim = simulated(log_value)
            if sim is None:
                return None
            out = np.sqrt(envelope(getattr(sim, channel)[:, 0] - base) ** 2 + floor ** 2)
            return out if np.all(np.isfinite(out)) else None
        return predicted

    predicted = predicted_on("tau", base_tau, noise)
    if by_position:
        predicted_q = predicted_on("q", base_q, q_noise)

    sizing, env_sized = (predicted_q, env_q_real) if by_position else (predicted, env_real)

    def loss(log_value: float) -> float:
        pred = sizing(log_value)
        return DIVERGED if pred is None else float(np.mean((env_sized[train] - pred[train]) ** 2))

    best = minimize_scalar(loss, bounds=(math.log(lo), math.log(hi)), method="bounded",
                           options={"xatol": 0.02, "maxiter": 14})
    pred = predicted(best.x)
    if pred is None or best.fun >= DIVERGED:
        pred = np.full_like(env_real, noise)       # no simulable size: an insignificant fit
    held = ~train
    null = np.full_like(env_real, noise)
    before = float(np.sqrt(np.mean((env_real[held] - null[held]) ** 2)))
    after = float(np.sqrt(np.mean((env_real[held] - pred[held]) ** 2)))
    sse = float(np.sum((env_real[train] - pred[train]) ** 2))
    sse0 = float(np.sum((env_real[train] - null[train]) ** 2))
    n = int(train.sum())
    n_eff = n / WINDOW
    value = float(math.exp(best.x))
    # uncertainty: curvature of the loss on the log scale, blocks of one window counted once
    h = 0.05
    curv = (loss(best.x + h) - 2 * best.fun + loss(best.x - h)) / h ** 2
    sigma2 = best.fun            # mean square misfit of the envelope the size was found on
    rel = math.sqrt(2 * sigma2 / max(curv, 1e-30) / n_eff) if curv > 0 else 0.0
    spread = _jackknife_spread(sizing, env_sized, train, best.x)
    rel = max(rel, spread) if np.isfinite(spread) else float("nan")   # nan: no interval is stated
    reduction = 1 - after / before if before > 0 else 0.0
    at_bound = min(best.x - math.log(lo), math.log(hi) - best.x) < 0.1   # the search ran out of range
    significant = reduction >= MIN_HELDOUT_REDUCTION and sse < 0.5 * sse0 and not at_bound
    stderr = value * rel
    if key == "backlash":
        # the play is read through the resolver: no better than one step (uniform error)
        stderr = max(stderr, joints[j].position_quantum / math.sqrt(12.0))
    fit = ChannelFit((effect,), "tau", j, np.array([value]), np.array([stderr]), (key,), (float("nan"),),
                     sse, sse0, before, after, 0.0 if significant else 1.0, WINDOW, pred, n, 1)
    return fit


def _jackknife_spread(predicted, env_real: np.ndarray, train: np.ndarray, x0: float) -> float:
    """Delete-a-block jackknife standard error of the size (log scale, i.e. relative), over
    contiguous stretches of the training rows, scaled so that 1.96 of it is a 95 % interval
    (fitting.block_jackknife_stderr). The envelope match is not sharp: the curvature alone
    gave intervals of about 1 % that missed the truth, and a split-half spread (one degree of
    freedom) still did. The simulations are made once on a grid around the fit; each
    stretch's refit is the parabola through the lowest loss on that grid."""
    steps = x0 + JACKKNIFE_GRID
    preds = [predicted(x) for x in steps]
    if any(p is None for p in preds):
        return float("nan")
    rows = np.flatnonzero(train)

    def refit(keep: np.ndarray) -> np.ndarray:
        loss = np.array([float(np.mean((env_real[keep] - p[keep]) ** 2)) for p in preds])
        k = int(np.clip(np.argmin(loss), 1, len(loss) - 2))
        a, b, c = loss[k - 1: k + 2]
        bend = a - 2 * b + c
        shift = 0.5 * (a - c) / bend if bend > 0 else 0.0
        return np.array([steps[k] + float(np.clip(shift, -1.0, 1.0)) * (steps[1] - steps[0])])

    return float(block_jackknife_stderr(refit, rows, 1)[0])
