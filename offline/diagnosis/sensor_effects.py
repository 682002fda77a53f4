"""Sensor effects read from the recording itself, against the nominal replay's sensors:
position (resolver/encoder) and torque-sensor quantisation, and a velocity channel that lags
the position channel.

Quantisation: the row-to-row changes of a quantised signal are whole multiples of one step.
Velocity lag: the recorded dq against the velocity the recorded q shows, shifted by 0 up to
the velocity's own correlation length (a longer shift could not be told from a different
motion; at most LAG_CAP cycles, and a best shift at that limit is reported as such); the nominal replay gives the shift that belongs to how the drive reports velocity,
and only the excess is a finding. Neither is a plant parameter, so these do not enter the
re-simulation; they explain a channel's mismatch and change how much of it to trust (a
coarse torque quantum is no "saturation at 0 N m").
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spacearm.offline.diagnosis.joint_units import units_of

MIN_CHANGES = 30             # nonzero row-to-row changes needed to read a step
ON_GRID = 0.95               # share of changes that must be whole multiples of the step
GRID_TOLERANCE = 0.03        # of a step
COARSER = 1.5                # recorded step / nominal step to call it a finding
LAG_CAP = 50                 # cycles: the longest velocity lag searched, whatever the recording's correlation
LAG_GAIN = 0.5               # the best shift must halve the misfit of the nominal shift
SMOOTH = 7                   # rows of the moving average both velocities are compared through


@dataclass
class SensorFinding:
    effect: str                  # "position_quantisation", "torque_quantisation", "velocity_latency"
    channel: str                 # "q_3", "tau_1", "dq_2"
    joint: int                   # 0-based
    params: dict[str, float]
    text: str


def quantum(x: np.ndarray, resolution: float | None = None) -> float | None:
    """The step a signal moves in, if it moves only in whole multiples of one step. With the
    nominal sensor's `resolution`, within half of it: a fine sensor (a 1 um linear encoder)
    on a constant-speed motion changes by nearly the same amount every row, on a 3 % grid
    of that change, without being coarse."""
    d = np.abs(np.diff(x))
    d = d[d > 1e-12 * max(1.0, float(np.max(np.abs(x))))]
    if len(d) < MIN_CHANGES:
        return None
    step = float(np.min(d[d >= np.percentile(d, 2)]))
    k = d / step
    tolerance = GRID_TOLERANCE if not resolution else min(GRID_TOLERANCE, 0.5 * resolution / step)
    on_grid = np.mean(np.abs(k - np.round(k)) < tolerance)
    # A joint at constant speed moves about the same whole number of fine steps every row, so
    # its changes can look like multiples of a coarse step; the values themselves then drift
    # off that coarse grid, which a quantised signal's values never do.
    level = (x - x[0]) / step
    values_on_grid = np.mean(np.abs(level - np.round(level)) < tolerance)
    return step if on_grid >= ON_GRID and values_on_grid >= ON_GRID else None


def lag_search_range(v: np.ndarray) -> int:
    """Cycles to search a velocity lag over: the lag where the velocity's autocorrelation falls
    below one half (a shift within it still lines up the same motion), at least 6 cycles and
    at most LAG_CAP."""
    x = v - v.mean()
    var = float(x @ x)
    if var <= 0.0:
        return 6
    for lag in range(1, min(LAG_CAP, len(x) // 4) + 1):
        if float(x[:-lag] @ x[lag:]) / var < 0.5:
            return max(6, lag)
    return min(LAG_CAP, max(6, len(x) // 4))


def velocity_lag(q: np.ndarray, dq: np.ndarray, dt: float) -> tuple[int, float, int] | None:
    """(shift in cycles that best matches dq to q's velocity, its gain over no shift, the
    longest shift searched)."""
    v = np.gradient(q, dt)
    if float(np.std(v)) < 1e-9 or float(np.std(dq)) < 1e-9 or len(q) < 24 + 2 * SMOOTH:
        return None
    # One resolver step per row is a large velocity on a slow joint: the same moving average
    # on both signals removes that chatter and leaves their relative shift as it was.
    kernel = np.ones(SMOOTH) / SMOOTH
    v, dq = (np.convolve(x, kernel, "same")[SMOOTH:-SMOOTH] for x in (v, dq))
    limit = min(lag_search_range(v), max(6, len(v) // 4))
    err = [float(np.sqrt(np.mean((dq[k:] - v[: len(v) - k]) ** 2))) for k in range(limit + 1)]
    best = int(np.argmin(err))
    return best, 1.0 - err[best] / max(err[0], 1e-300), limit


def sensor_findings(q: np.ndarray, dq: np.ndarray, tau: np.ndarray, dt: float,
                    nominal: tuple[np.ndarray, np.ndarray] | None, quanta: tuple[list[float], list[float]] | None,
                    active: list[int], kinds: list[str] | None = None,
                    commanded: np.ndarray | None = None) -> list[SensorFinding]:
    """Findings for the joints in `active` (0-based). `nominal`: (q, dq) of the nominal
    replay, whose own velocity shift is the reference; `quanta`: the nominal sensors' steps
    (position, torque) per joint. Without them (another arm), only a velocity shift of 2
    cycles or more and torque steps of 1 mN m or more are named."""
    out: list[SensorFinding] = []
    for j in active:
        u = units_of(kinds[j] if kinds else "revolute")     # prismatic: m, N
        for effect, name, real, ref, unit in (("position_quantisation", "q", q, 0, u.position),
                                              ("torque_quantisation", "tau", tau, 1, u.effort)):
            step = quantum(real[:, j], quanta[ref][j] if quanta is not None else None)
            if step is None:
                continue
            nominal_step = quanta[ref][j] if quanta is not None else None
            if nominal_step is not None and step < COARSER * nominal_step:
                continue
            if nominal_step is None and effect == "torque_quantisation" and step < 1e-3:
                continue
            was = f" (the nominal sensor: {nominal_step:.3g} {unit})" if nominal_step else ""
            what = "resolver/encoder" if name == "q" else "torque sensor"
            out.append(SensorFinding(effect, f"{name}_{j + 1}", j, {"quantum": step},
                                     f"joint {j + 1}: {what} quantised in steps of {step:.3g} {unit}{was}"))
        if commanded is not None:
            out += scale_and_offset(q[:, j], commanded[:, j], j, quanta[0][j] if quanta else 0.0, u.position,
                                    nominal[0][:, j] if nominal is not None else None)
        if not np.any(dq[:, j]):
            continue
        lag = velocity_lag(q[:, j], dq[:, j], dt)
        if lag is None:
            continue
        reference = velocity_lag(nominal[0][:, j], nominal[1][:, j], dt) if nominal is not None else (0, 0.0)
        base = reference[0] if reference is not None else 0
        extra = lag[0] - base
        if extra >= (1 if nominal is not None else 2) and lag[1] >= LAG_GAIN:
            at_limit = lag[0] == lag[2]
            limit = (f"; the search stopped at its limit of {lag[2]} cycles (the velocity's correlation length"
                     f"{', capped' if lag[2] == LAG_CAP else ''}): the lag may be longer") if at_limit else ""
            out.append(SensorFinding("velocity_latency", f"dq_{j + 1}", j, {"velocity_latency_cycles": float(extra),
                                                                           "velocity_latency_s": extra * dt,
                                                                           "search_limit_cycles": float(lag[2]),
                                                                           "at_search_limit": float(at_limit)},
                                     f"joint {j + 1}: velocity channel lags the position channel by {extra} "
                                     f"cycle{'s' if extra > 1 else ''} ({1e3 * extra * dt:.3g} ms){limit}"))
    return out


DEGREES = 180.0 / np.pi
SCALE_TOLERANCE = 0.02       # relative: a slope within this of 1 is no scale error
OFFSET_QUANTA = 10           # a constant difference of more quanta than this is an offset


def scale_and_offset(q: np.ndarray, q_nominal: np.ndarray, j: int, quantum: float, unit: str,
                     replayed: np.ndarray | None = None) -> list[SensorFinding]:
    """A position column in the wrong unit or scale (degrees for radians, a gear ratio) or off
    by a constant (an encoder zero): the recorded q against the commanded q (what the servo
    held it to; the replay itself starts from the recorded, wrongly scaled first row) as
    a q_commanded + b. Named only where that line explains most of the difference."""
    X = np.column_stack([q_nominal, np.ones_like(q_nominal)])
    if float(np.ptp(q_nominal)) < 1e-3:
        return []
    (a, b), *_ = np.linalg.lstsq(X, q, rcond=None)
    before = float(np.sqrt(np.mean((q - q_nominal) ** 2)))
    after = float(np.sqrt(np.mean((q - a * q_nominal - b) ** 2)))
    if not after < 0.2 * before:
        return []
    name = f"q_{j + 1}"
    if abs(a / DEGREES - 1.0) < SCALE_TOLERANCE:
        return [SensorFinding("position_units", name, j, {"scale": float(a)},
                              f"joint {j + 1}: the position column is in degrees, not radians (x {a:.4g})")]
    if abs(a - 1.0) > SCALE_TOLERANCE:
        return [SensorFinding("position_scale", name, j, {"scale": float(a), "offset": float(b)},
                              f"joint {j + 1}: position column scaled x {a:.4g} against the replay (a gear ratio or "
                              "encoder resolution in the conversion)")]
    if replayed is not None:
        # the servo's own steady error (a slide's droop under its load) shows in the replay too
        b -= float(np.linalg.lstsq(X, replayed, rcond=None)[0][1])
    if abs(b) > OFFSET_QUANTA * max(quantum, 1e-9):
        return [SensorFinding("position_offset", name, j, {"offset": float(b)},
                              f"joint {j + 1}: position column offset by {b:.3g} {unit} (an encoder zero or "
                              "calibration offset)")]
    return []
