"""The catalogue of candidate effects the diagnosis can name from a joint/F-T recording.

Each candidate predicts the residual (recording minus nominal simulation) of one channel
from the nominal simulation's own signals, as a linear model in its size parameters with at
most one nonlinear shape parameter scanned on a grid. The drive servo holds the link on its
reference, so a missing disturbance torque d(t) shows almost one-to-one in the motor torque
residual: a friction or load candidate predicts r_tau = d(t).

Effects in the plant that a joint/F-T recording cannot show (encoder bias with link-side
resolvers, thermal growth of the links, F/T scale error without contact) are not candidates:
they need tool-pose data (calibration).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

VELOCITY_DEADBAND = 1e-4     # rad/s: slower than this counts as at rest


@dataclass
class Signals:
    """The nominal simulation of one joint (or the F/T axis), row by row."""
    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    tau: np.ndarray
    dt: float


@dataclass(frozen=True)
class Candidate:
    effect: str                  # catalogue name (also the benchmark's)
    channel: str                 # "tau", "q" or "wrench"
    columns: tuple[str, ...]     # names of the linear parameters
    grid: tuple[float, ...]      # values of the shape parameter (empty: none)
    features: Callable[[Signals, float], np.ndarray]   # (N, p)
    fixed_gain: bool = False     # the prediction has no free size (latency, saturation)


# Stribeck decay speeds tried, rad/s: roughly 25 % steps, from the slowest speed the drive
# resolves smoothly to where the bump is as wide as the running speeds themselves
STRIBECK_VELOCITIES = tuple(float(v) for v in np.geomspace(0.002, 0.06, 16))


def _sign(v: np.ndarray) -> np.ndarray:
    return np.where(np.abs(v) > VELOCITY_DEADBAND, np.sign(v), 0.0)


def _delay(x: np.ndarray, n: int) -> np.ndarray:
    out = np.empty_like(x)
    out[:n] = x[0]
    out[n:] = x[:-n]
    return out


def _saturation(s: Signals, limit: float) -> np.ndarray:
    return (np.clip(s.tau, -limit, limit) - s.tau)[:, None]


JOINT_CANDIDATES: tuple[Candidate, ...] = (
    Candidate("coulomb", "tau", ("coulomb_friction",), (), lambda s, _: _sign(s.dq)[:, None]),
    Candidate("viscous", "tau", ("viscous_friction",), (), lambda s, _: s.dq[:, None]),
    Candidate("stribeck", "tau", ("stribeck_friction",), STRIBECK_VELOCITIES,
              lambda s, vs: (_sign(s.dq) * np.exp(-(s.dq / vs) ** 2))[:, None]),
    Candidate("gravity_load", "tau", ("load_cos", "load_sin"), (),
              lambda s, _: np.column_stack([np.cos(s.q), -np.sin(s.q)])),
    Candidate("torque_saturation", "tau", ("gain",), ("quantiles",), _saturation, fixed_gain=True),
    Candidate("latency", "q", ("gain",), (1, 2, 3, 4, 5, 6),
              lambda s, n: (_delay(s.q, int(n)) - s.q)[:, None], fixed_gain=True),
)

FT_CANDIDATES: tuple[Candidate, ...] = (
    Candidate("ft_bias", "wrench", ("bias",), (), lambda s, _: np.ones((len(s.t), 1))),
    Candidate("ft_drift", "wrench", ("bias", "drift"), (), lambda s, _: np.column_stack([np.ones(len(s.t)), s.t])),
)

# A prismatic joint's load: the plant's G cos(angle) along the axis, the same at every position
# (plant.py). One constant column; cos(q) and -sin(q) of a position in metres only stand in for
# a constant over a short stroke and trade off against each other over a long one.
LOAD_FORCE = Candidate("gravity_load", "tau", ("load_force",), (), lambda s, _: np.ones((len(s.t), 1)))


def joint_candidates(kind: str = "revolute") -> tuple[Candidate, ...]:
    """The catalogue for one joint of this kind ("revolute" or "prismatic")."""
    if kind != "prismatic":
        return JOINT_CANDIDATES
    return tuple(LOAD_FORCE if c.effect == "gravity_load" else c for c in JOINT_CANDIDATES)


# Pairs on one joint's torque channel (two effects at once): features side by side.
TORQUE_PAIRS: tuple[tuple[str, str], ...] = (("coulomb", "viscous"), ("coulomb", "gravity_load"),
                                             ("viscous", "gravity_load"), ("stribeck", "viscous"))


def by_name(name: str, kind: str = "revolute") -> Candidate:
    for c in joint_candidates(kind) + FT_CANDIDATES:
        if c.effect == name:
            return c
    raise KeyError(name)
