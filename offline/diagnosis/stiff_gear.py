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
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.stats import f as f_dist

from spacearm.offline.diagnosis.direct_sim import simulate
from spacearm.offline.diagnosis.fitting import MIN_HELDOUT_REDUCTION, SIGNIFICANCE, ChannelFit, correlation_length
from spacearm.firmware_sim.plant import PlantConfig

# Softer than this the loop rings (gear_effects' case); stiffer than 1e6 N m/rad the explicit
# two-mass step is no longer stable (as in gear_effects).
STIFFNESS_RANGE = (3e4, 1e6)


def fit_stiff_gear(nominal: PlantConfig, q_cmd: np.ndarray, dt: float, q0: np.ndarray, base_tau: np.ndarray,
                   residual: np.ndarray, j: int, train: np.ndarray,
                   dq_cmd: np.ndarray | None = None) -> ChannelFit | None:
    """Joint `j`'s stiffness from `residual` (recorded torque minus the nominal replay) against
    `base_tau` (the ideal-sensor nominal replay's torque); None if no stiffness simulates."""
    joints = [nominal.joint_params(i) for i in range(q_cmd.shape[1])]
    sims: dict[float, np.ndarray | None] = {}

    def predicted(log_k: float) -> np.ndarray | None:
        if log_k not in sims:
            p = joints[j].model_copy(update={"joint_stiffness": float(math.exp(log_k)), "resolver_arcsec": 0.0,
                                            "encoder_quantum": 0.0, "torque_noise": 0.0})
            js = list(joints)
            js[j] = p
            try:
                with np.errstate(all="raise"):
                    sim = simulate(nominal.model_copy(update={"joints": js}), q_cmd, dt, q0=q0, joints=[j],
                                   dq_cmd=dq_cmd)
                out = sim.tau[:, 0] - base_tau
                sims[log_k] = out if np.all(np.isfinite(out)) else None
            except (OverflowError, FloatingPointError, ValueError):
                sims[log_k] = None
        return sims[log_k]

    def loss(log_k: float) -> float:
        pred = predicted(log_k)
        return 1e300 if pred is None else float(np.mean((residual[train] - pred[train]) ** 2))

    lo, hi = (math.log(v) for v in STIFFNESS_RANGE)
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
    fit = ChannelFit(("elasticity",), "tau", j, np.array([value]), np.array([value * rel]), ("joint_stiffness",),
                     (float("nan"),), sse, sse0, before, after, p_value, block, pred, n, 1, judged_by="stiff gear")
    return fit


def significant(fit: ChannelFit | None) -> bool:
    return fit is not None and fit.p_value < SIGNIFICANCE and fit.heldout_reduction >= MIN_HELDOUT_REDUCTION
