"""Modified D-H rows (Craig) from joint axis lines, so an imported arm keeps our calibration
error parameterisation (a, alpha, d, theta, and Hayati beta where consecutive axes are parallel).

Frame i has z along joint i's axis and x along the common normal to axis i+1, origin where
that normal leaves axis i. Frame 0 is frame 1 at q = 0 (the base transform carries where it
is), so row 1 is zero apart from the joint itself. For parallel axes the common normal is
taken through the previous normal's foot (d = 0) and the joint gets a nominal beta = 0:
a small tilt of a parallel axis then changes beta instead of sending d to infinity (Hayati).
A prismatic joint's line is only a direction; it is placed through the joint's origin.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]
PARALLEL = 1e-9   # |z_i x z_j| below this: parallel axes
MEET = 1e-12      # m: axes closer than this intersect


@dataclass(frozen=True)
class DHRowFit:
    a: float        # a_{i-1}, m
    alpha: float    # alpha_{i-1}, rad
    d: float        # d_i, m
    theta: float    # theta_i at q = 0, rad
    hayati: bool    # axes i-1 and i parallel: model beta_i


@dataclass(frozen=True)
class DHFit:
    rows: list[DHRowFit]
    frames: list[Array]   # frame i (4x4, base link coordinates) at q = 0
    base: Array           # base link -> frame 0 (= frame 1 at q = 0)


def _perpendicular(z: Array, hint: Array | None) -> Array:
    """A unit vector perpendicular to z, as close to `hint` as possible."""
    for v in ([hint] if hint is not None else []) + [np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])]:
        x = v - (v @ z) * z
        if np.linalg.norm(x) > 1e-6:
            return x / np.linalg.norm(x)
    raise AssertionError("unreachable: x or y is always off a unit z")


def _normal(p1: Array, z1: Array, p2: Array, z2: Array, x_hint: Array | None
            ) -> tuple[Array, Array, bool]:
    """Foot of the common normal on line 1, unit direction towards line 2, parallel flag."""
    cross = np.cross(z1, z2)
    if np.linalg.norm(cross) < PARALLEL:
        # through p1 (the previous normal's foot): d = 0 for this joint
        w = p2 - p1
        x = w - (w @ z1) * z1
        if np.linalg.norm(x) < MEET:
            return p1, _perpendicular(z1, x_hint), True
        return p1, x / np.linalg.norm(x), True
    # closest points of two skew lines
    w = p1 - p2
    b = z1 @ z2
    denom = 1.0 - b * b
    t1 = (b * (z2 @ w) - (z1 @ w)) / denom
    t2 = ((z2 @ w) - b * (z1 @ w)) / denom
    foot1, foot2 = p1 + t1 * z1, p2 + t2 * z2
    x = foot2 - foot1
    if np.linalg.norm(x) < MEET:
        x = cross if x_hint is None or cross @ x_hint >= 0.0 else -cross
    return foot1, x / np.linalg.norm(x), False


def _frame(origin: Array, x: Array, z: Array) -> Array:
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, np.cross(z, x), z, origin
    return T


def fit_modified_dh(points: list[Array], axes: list[Array]) -> DHFit:
    """Rows for joints whose axis i passes through points[i] along unit axes[i] (q = 0)."""
    n = len(axes)
    z = [np.asarray(a, float) / np.linalg.norm(a) for a in axes]
    origins: list[Array] = []
    xs: list[Array] = []
    parallel = [False] * n
    foot = np.asarray(points[0], float)   # where the previous normal meets axis i
    for i in range(n):
        if i + 1 < n:
            p_next = np.asarray(points[i + 1], float)
            o, x, parallel[i + 1] = _normal(foot, z[i], p_next, z[i + 1], xs[-1] if xs else None)
            # x is perpendicular to axis i+1, so this point lies on it: the next joint's start
            next_foot = o + ((p_next - o) @ x) * x
        else:
            o, x, next_foot = foot, _perpendicular(z[i], xs[-1] if xs else None), foot
        origins.append(o)
        xs.append(x)
        foot = next_foot
    frames = [_frame(origins[i], xs[i], z[i]) for i in range(n)]
    rows = [DHRowFit(0.0, 0.0, 0.0, 0.0, False)]
    for i in range(1, n):
        xp, zp, zi = xs[i - 1], z[i - 1], z[i]
        alpha = math.atan2(float(np.cross(zp, zi) @ xp), float(zp @ zi))
        a = float((origins[i] - origins[i - 1]) @ xp)
        meet = origins[i - 1] + a * xp
        d = float((origins[i] - meet) @ zi)
        theta = math.atan2(float(np.cross(xp, xs[i]) @ zi), float(xp @ xs[i]))
        rows.append(DHRowFit(a, alpha, d, theta, parallel[i]))
    return DHFit(rows=rows, frames=frames, base=frames[0])
