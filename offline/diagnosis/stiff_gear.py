"""A stiff elastic gear that does not make the drive ring, found sample by sample.

The drive closes its loop on the link resolver, so the motor has to run ahead of the link by
the gear's deflection c/k (c the torque through the gear): the drive torque becomes
J_m (q + c/k)'' + c instead of J_m q'' + c. Below about 5e4 N m/rad (this test bed) the
extra compliance makes the loop ring and the gear effects are found by their envelope
(gear_effects). Stiffer, the loop stays stable and the effect is a small, smooth torque
difference with a reproducible phase: a replay with the stiffness reproduces it sample by
sample, so here the size is found by least squares on the torque residual itself, over a
log-scale stiffness range (bounded one-dimensional search, scipy). Backlash gives no such
smooth, phase-locked term (its play makes the drive hunt), and an effect-free recording has
nothing for a finite stiffness to explain: both are left to the held-out test below and to
the held-out re-simulation that judges every finding.

Stiffer still (1e5-2e5 N m/rad on the test bed), that smooth term is a few per cent of the
torque residual and the effect shows mostly in the servo's quantisation chatter: against the
resolver, a compliant gear makes the drive chatter harder and in its own pattern, locked to
the motion. A replay with ideal sensors has no chatter and explained none of it (held-out
reduction 0-4 % where the true plant's own replay reaches 13-40 %, development seed 7001's
elasticity cases); a replay with the nominal's sensors reproduces it (2.92 -> 2.05 N m at the
true stiffness, 2.37 at 0.8x, 2.02 at 1.25x on one of them). That loss is rugged in the
stiffness (the chatter pattern jumps), so it is searched on a log grid and refined within
one grid step of the best point (fit_chattering_gear).
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.stats import f as f_dist

from spacearm.offline.diagnosis.direct_sim import simulate
from spacearm.offline.diagnosis.fitting import (JACKKNIFE_BLOCKS, MIN_HELDOUT_REDUCTION, SIGNIFICANCE, ChannelFit,
                                                correlation_length)
from spacearm.firmware_sim.plant import PlantConfig

# Softer than this the loop rings (gear_effects' case); stiffer than 1e6 N m/rad the explicit
# two-mass step is no longer stable (as in gear_effects).
STIFFNESS_RANGE = (3e4, 1e6)


# The chattering gear's grid: this many log-spaced stiffnesses over STIFFNESS_RANGE (29 % apart:
# the basin of the true stiffness was about +-20 % wide on the development cases), then a
# bounded search within one grid step of the best.
CHATTER_GRID = 15


def fit_stiff_gear(nominal: PlantConfig, q_cmd: np.ndarray, dt: float, q0: np.ndarray, base_tau: np.ndarray,
                   residual: np.ndarray, j: int, train: np.ndarray,
                   dq_cmd: np.ndarray | None = None, sensors: bool = False) -> ChannelFit | None:
    """Joint `j`'s stiffness from `residual` (recorded torque minus the nominal replay) against
    `base_tau` (the ideal-sensor nominal replay's torque; with `sensors`, the nominal replay's
    own, and the stiffness replays keep the nominal's resolver and encoder: see
    fit_chattering_gear); None if no stiffness simulates."""
    joints = [nominal.joint_params(i) for i in range(q_cmd.shape[1])]
    sims: dict[float, np.ndarray | None] = {}
    ideal = {} if sensors else {"resolver_arcsec": 0.0, "encoder_quantum": 0.0}

    def predicted(log_k: float) -> np.ndarray | None:
        if log_k not in sims:
            p = joints[j].model_copy(update={"joint_stiffness": float(math.exp(log_k)), "torque_noise": 0.0} | ideal)
            js = list(joints)
            js[j] = p
            try:
                with np.errstate(all="raise"):
                    sim = simulate(nominal.model_copy(update={"joints": js}), q_cmd, dt, q0=q0, joints=[j],
                                   dq_cmd=dq_cmd, wrench=False)
                out = sim.tau[:, 0] - base_tau
                sims[log_k] = out if np.all(np.isfinite(out)) else None
            except (OverflowError, FloatingPointError, ValueError):
                sims[log_k] = None
        return sims[log_k]

    def loss(log_k: float) -> float:
        pred = predicted(log_k)
        return 1e300 if pred is None else float(np.mean((residual[train] - pred[train]) ** 2))

    lo, hi = (math.log(v) for v in STIFFNESS_RANGE)
    if sensors:
        grid = np.linspace(lo, hi, CHATTER_GRID)
        i = int(np.argmin([loss(float(x)) for x in grid]))
        step = grid[1] - grid[0]
        near = (max(lo, grid[i] - step), min(hi, grid[i] + step))
        best = minimize_scalar(loss, bounds=near, method="bounded", options={"xatol": 0.02, "maxiter": 8})
        if loss(float(grid[i])) < best.fun:
            best.x, best.fun = float(grid[i]), loss(float(grid[i]))
    else:
        best = minimize_scalar(loss, bounds=(lo, hi), method="bounded", options={"xatol": 0.02, "maxiter": 14})
    pred = predicted(best.x)
    if pred is None:
        return None
    held = ~train
    sse = float(np.sum((residual[train] - pred[train]) ** 2))
    sse0 = float(np.sum(residual[train] ** 2))
    before = float(np.sqrt(np.mean(residual[held] ** 2)))
    after = float(np.sqrt(np.mean((residual[held] - pred[held]) ** 2)))
    n = int(train.sum())
    block = correlation_length(residual[train] - pred[train])
    n_eff = max(n / block, 3.0)
    # one parameter: F test on the training rows, correlated rows counted once per block
    f_stat = (sse0 - sse) / max(sse / (n_eff - 1.0), 1e-300)
    p_value = float(f_dist.sf(f_stat, 1, n_eff - 1.0)) if sse < sse0 else 1.0
    at_bound = min(best.x - lo, hi - best.x) < 0.1      # the search ran out of range: no size known
    if at_bound:
        p_value = 1.0
    value = float(math.exp(best.x))
    h = 0.05
    curv = (loss(best.x + h) - 2 * best.fun + loss(best.x - h)) / h ** 2
    rel = math.sqrt(2 * best.fun / curv / n_eff) if curv > 0 else float("inf")
    if sensors:
        # the chatter's loss is rugged: its curvature at the best point said +-1-3 % where the
        # fits missed the truth by 1-6 % (development seed 7001); the spread of the best
        # stiffness over the replays already made, each training block left out in turn, is wider
        rel = max(rel, _jackknife_spread({x: p for x, p in sims.items() if p is not None}, residual, train))
    fit = ChannelFit(("elasticity",), "tau", j, np.array([value]), np.array([value * rel]), ("joint_stiffness",),
                     (float("nan"),), sse, sse0, before, after, p_value, block, pred, n, 1, judged_by="stiff gear")
    return fit


def _jackknife_spread(predictions: dict[float, np.ndarray], residual: np.ndarray, train: np.ndarray) -> float:
    """Block-jackknife standard error of the best log stiffness among the `predictions` already
    replayed (log stiffness -> torque term), JACKKNIFE_BLOCKS contiguous training blocks."""
    rows = np.flatnonzero(train)
    keys = np.array(sorted(predictions))
    errors = np.array([(residual[rows] - predictions[k][rows]) ** 2 for k in keys])
    blocks = np.array_split(np.arange(len(rows)), JACKKNIFE_BLOCKS)
    picks = np.array([keys[int(np.argmin(np.delete(errors, b, axis=1).sum(axis=1)))] for b in blocks])
    m = len(blocks)
    return float(math.sqrt((m - 1) / m * np.sum((picks - picks.mean()) ** 2)))


def fit_chattering_gear(nominal: PlantConfig, q_cmd: np.ndarray, dt: float, q0: np.ndarray, sim_tau: np.ndarray,
                        residual: np.ndarray, j: int, train: np.ndarray,
                        dq_cmd: np.ndarray | None = None) -> ChannelFit | None:
    """Joint `j`'s stiffness from the chatter it adds (see the module's note): replays with the
    nominal's sensors against `sim_tau`, the nominal replay's torque of the joint."""
    return fit_stiff_gear(nominal, q_cmd, dt, q0, sim_tau, residual, j, train, dq_cmd, sensors=True)


def chatters_more(residual: np.ndarray, chatter: float) -> bool:
    """Whether the torque residual's RMS stands above what two equally valid nominal replays
    differ by (`chatter`) by more than CHATTER_SCREEN: only then is the grid of replays run."""
    return float(np.sqrt(np.mean(residual ** 2))) > CHATTER_SCREEN * chatter


# Residual RMS / null chatter: 0.26-1.23 on the 50 effect-free moving joints of development seed
# 7001's elasticity cases, 1.48-1.78 on the five elastic joints of 1.1e5-1.9e5 N m/rad (one of
# 1.8e5 on point-to-point moves sat at 1.07 and is missed). A screen for cost, not the test: the
# fit must still pass the F test and the held-out reduction.
CHATTER_SCREEN = 1.35


def significant(fit: ChannelFit | None) -> bool:
    return fit is not None and fit.p_value < SIGNIFICANCE and fit.heldout_reduction >= MIN_HELDOUT_REDUCTION
