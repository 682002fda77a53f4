"""The experiment that settles it: when the diagnosis names two laws that explain a recording
equally well (Coulomb or viscous friction at one speed, Stribeck or Coulomb one way), or a
joint never moved, design a short excitation within the arm's limits that separates them:
each such joint in turn, out and back at several speeds (both directions, so Coulomb's
sign change shows; several speeds, so viscous friction's growth shows), with a dwell at rest
before every start (so stiction's break-away shows). The other joints hold still.

    traj = design_experiment(joints, q_start, limits_from_arm(arm_file, n))

The same experiment as a list of moves (``experiment_moves``) is what ``diagnose --run``
sends to a running daemon: each a joint move at a fraction of the joint limits after a dwell.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spacearm.offline.diagnosis.trajectory import Trajectory

SPEED_FRACTIONS = (0.2, 0.45, 1.0)   # of the usable speed: three speeds, 5x apart
SPEED_MARGIN = 0.8                     # use 80 % of the joint's velocity limit ...
STROKE = 0.15                         # rad out and back at each speed (less where the limits are closer)
ACCELERATION_SHARE = 0.25             # ... and a quarter of its acceleration limit: gentle starts, no servo transients
DWELL = 1.5                           # s at rest before each start


@dataclass
class JointLimit:
    lower: float
    upper: float
    velocity: float
    acceleration: float


def limits_from_arm(arm_file: str | Path, n: int) -> list[JointLimit]:
    """Per-joint limits of an arm file; joints beyond the file's count take its last joint's."""
    from spacearm.base.config.arm import load_arm_config
    joints = load_arm_config(arm_file).joints
    out = [JointLimit(j.limits.lower, j.limits.upper, j.limits.velocity, j.limits.acceleration) for j in joints]
    return (out + [out[-1]] * n)[:n]


def limits_from_urdf(arm) -> list[JointLimit]:
    """Per-joint limits of the user's URDF (rigid_body.ArmModel). A URDF states no acceleration
    limit: a second to reach full speed is assumed."""
    m = arm.model
    return [JointLimit(float(m.lowerPositionLimit[j]), float(m.upperPositionLimit[j]), float(m.velocityLimit[j]),
                       float(m.velocityLimit[j])) for j in range(arm.n)]


def _move(distance: float, v: float, a: float, dt: float) -> np.ndarray:
    """Positions (relative, from 0) of a trapezoidal move over `distance` (signed)."""
    d = abs(distance)
    if d == 0.0:
        return np.zeros(1)
    v = min(v, math.sqrt(d * a))            # a triangle when the stroke is too short to cruise
    t_acc = v / a
    t_total = d / v + t_acc
    t = np.arange(0.0, t_total + dt, dt)
    t = np.minimum(t, t_total)
    s = np.where(t < t_acc, 0.5 * a * t ** 2,
                 np.where(t < t_total - t_acc, 0.5 * a * t_acc ** 2 + v * (t - t_acc),
                          d - 0.5 * a * (t_total - t) ** 2))
    return math.copysign(1.0, distance) * s


@dataclass
class ExperimentMove:
    """One move of the experiment: after `dwell` s at rest, joint `joint` (0-based) goes to
    `target` (all joints, rad) at `speed`, a fraction of that joint's velocity limit."""
    joint: int
    target: np.ndarray
    speed: float
    dwell: float = DWELL


def experiment_moves(joints: list[int], q_start: np.ndarray, limits: list[JointLimit]) -> list[ExperimentMove]:
    """Speed by speed, each given joint out and back; the arm ends where it started. Speed
    before joint, so that with several joints the held-out end of the recording (the last
    40 %, the fastest moves) still shows every one of them: joint by joint, the first joint's
    fit had nothing held out to be confirmed on."""
    q = np.asarray(q_start, float).copy()
    strokes, signs = {}, {}
    for j in joints:
        lim = limits[j]
        room_up, room_down = lim.upper - q[j], q[j] - lim.lower
        strokes[j] = min(STROKE, 0.9 * max(room_up, room_down))
        signs[j] = 1.0 if room_up >= room_down else -1.0
    moves = []
    for fraction in SPEED_FRACTIONS:
        for j in joints:
            for direction in (signs[j], -signs[j]):       # out and back: both directions at this speed
                q[j] += direction * strokes[j]
                moves.append(ExperimentMove(j, q.copy(), fraction * SPEED_MARGIN))
    return moves


def design_experiment(joints: list[int], q_start: np.ndarray, limits: list[JointLimit], dt: float = 0.02
                      ) -> Trajectory:
    """The excitation trajectory (from q_start, back to it) for the given 0-based joints:
    the moves of `experiment_moves` as trapezoids, with a dwell before each and at the end."""
    rows = [np.asarray(q_start, float).copy()]
    for move in experiment_moves(joints, q_start, limits):
        rows += [rows[-1].copy() for _ in range(int(round(move.dwell / dt)))]
        base, lim = rows[-1].copy(), limits[move.joint]
        for s in _move(move.target[move.joint] - base[move.joint], move.speed * lim.velocity,
                       ACCELERATION_SHARE * lim.acceleration, dt)[1:]:
            p = base.copy()
            p[move.joint] = base[move.joint] + s
            rows.append(p)
    rows += [rows[-1].copy() for _ in range(int(round(DWELL / dt)))]
    q_all = np.array(rows)
    return Trajectory(dt * np.arange(len(q_all)), q_all)


def joints_to_excite(diagnosis, q: np.ndarray, min_travel: float) -> list[int]:
    """Joints with an ambiguous finding or a torque mismatch nothing explains (0-based); if
    there are none, the joints that did not move. Not both: one experiment answers one kind
    of question."""
    ambiguous = sorted({f.fit.index for f in diagnosis.findings if f.alternatives and f.fit.channel == "tau"}
                       | {int(c.name[4:]) - 1 for c in diagnosis.unexplained if c.name.startswith("tau_")})
    return ambiguous or [j for j in range(q.shape[1]) if np.ptp(q[:, j]) <= min_travel]
