"""Penalty contact of a box-shaped male part entering a chamfered rectangular cavity.

One primitive serves both contacts of the ORU cell: the ORU entering its store slot
(10 mm chamfer, 0.5 mm clearance) and the ORU adapter head entering the end effector's
guide blocks (12 mm arc guide, the capture tolerance > 10 mm). Frames:

- female F: origin at the centre of the opening, the cavity along -z, outside at z > 0;
- male M: origin at the tip face centre, the body along +z (tip first into the cavity).

The solid around the cavity is, per side, the convex wedge {below the opening plane,
outside the wall, beyond the 45-degree chamfer plane}; a point inside it is pushed out along
the nearest of the three planes, and a point below the floor (inside the opening's footprint) is pushed up; the body ends `rim` beyond
the chamfer, so a part passing beside it feels nothing. The male box is
sampled at its 8 corners plus the points where its 4 long edges cross the opening and the
chamfer-foot planes: for a convex box against planar walls the deepest penetration is at one
of these, so 16 points (vectorised numpy) capture face, edge and corner contact.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

SQRT_HALF = math.sqrt(0.5)
CLEAR = 1e-9       # m: rounding margin of the quick no-contact test (the sample points' own error is ~1e-17 m)
# np.clip's own ufunc: the same values without np.clip's dispatch (~8 us a call, twice a sub-step).
_clip = getattr(getattr(getattr(np, "_core", None), "umath", None), "clip", np.clip)


@dataclass(frozen=True)
class Cavity:
    half_x: float      # m, inner half width (male half width + clearance)
    half_y: float
    chamfer: float     # m, 45-degree guide width at the opening
    depth: float       # m, floor below the opening (0: a closed top, e.g. an occupied slot)
    rim: float = 0.03  # m of top face around the chamfer: the body's outer edge


@dataclass(frozen=True)
class MaleBox:
    half_x: float
    half_y: float
    length: float      # m along +z from the tip face

    def corners(self) -> np.ndarray:
        """(8, 3) corners in the male frame: tip face first (read-only, shared)."""
        return self._corners

    @cached_property
    def _corners(self) -> np.ndarray:
        c = np.array([[1, 1, 0], [1, -1, 0], [-1, 1, 0], [-1, -1, 0],
                      [1, 1, 1], [1, -1, 1], [-1, 1, 1], [-1, -1, 1]], float)
        c = c * (self.half_x, self.half_y, self.length)
        c.setflags(write=False)
        return c

    @cached_property
    def radius(self) -> float:
        """m from the box's centre to its corners (every point of it is this close)."""
        return math.sqrt(self.half_x ** 2 + self.half_y ** 2 + (0.5 * self.length) ** 2) * (1.0 + 1e-12)

    @cached_property
    def _samples(self) -> np.ndarray:
        """sample_points' rows that do not depend on the pose: the corners, the long edges' x, y."""
        out = np.empty((16, 3))
        out[:8] = self._corners
        out[8:12, :2] = out[12:, :2] = self._corners[:4, :2]
        out.setflags(write=False)
        return out


@dataclass(frozen=True)
class ContactLaw:
    stiffness: float          # N/m per contact point
    damping: float            # N s/m per contact point
    friction: float           # Coulomb coefficient
    slip_velocity: float      # m/s, regularisation of the friction law


def sample_points(box: MaleBox, F_T_M: np.ndarray, chamfer: float) -> np.ndarray:
    """(16, 3) sample points in male coordinates for the current relative pose."""
    corners = box.corners()
    xy = corners[:4]
    R, t = F_T_M[:3, :3], F_T_M[:3, 3]
    base_z = xy @ R[2, :] + t[2]          # z_F of each long edge at its tip end
    slope = R[2, 2]                       # dz_F per unit length along the edge
    if abs(slope) < 1e-6:
        return corners
    out = box._samples.copy()
    out[8:12, 2] = _clip(-base_z / slope, 0.0, box.length)
    out[12:, 2] = _clip((-chamfer - base_z) / slope, 0.0, box.length)
    return out


def cavity_forces(cavity: Cavity, law: ContactLaw, p: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Forces (n, 3) on the male points p (n, 3, female frame) moving with velocity v."""
    n = len(p)
    depth = -p[:, 2]
    forces = np.zeros((n, 3))
    u = np.abs(p[:, :2])                                  # both sides' distances at once
    beside = (u[:, 0] < cavity.half_x + cavity.chamfer + cavity.rim) & (u[:, 1] < cavity.half_y + cavity.chamfer + cavity.rim)
    deep = beside & (depth > 0.0)                         # below the opening, over the body
    if not deep.any():
        return forces      # (the floor lies deeper still)
    halves = np.array([cavity.half_x, cavity.half_y])
    walls = u - halves
    chams = (u + depth[:, None] - halves - cavity.chamfer) * SQRT_HALF
    insides = deep[:, None] & (walls > 0.0) & (chams > 0.0)
    normals = np.zeros((n, 3))
    pen = np.zeros(n)
    for axis in np.flatnonzero(insides.any(axis=0)).tolist():
        inside, wall, cham = insides[:, axis], walls[:, axis], chams[:, axis]
        side = np.sign(p[:, axis])
        # The chamfer face spans depths 0..c only: below it the nearest surface is the wall (a
        # face sliding past the chamfer's foot is pushed sideways, not up).
        candidates = np.column_stack([wall, np.where(depth < cavity.chamfer, cham, np.inf), depth])
        which = np.argmin(candidates, axis=1)
        pen[:] = np.where(inside, candidates[np.arange(n), which], 0.0)
        normals[:] = 0.0
        normals[:, axis] = np.where(which == 0, -side, np.where(which == 1, -side * SQRT_HALF, 0.0))
        normals[:, 2] = np.where(which == 0, 0.0, np.where(which == 1, SQRT_HALF, 1.0))
        forces += _penalty(law, pen, normals, v)
    floor = np.where((u[:, 0] < cavity.half_x) & (u[:, 1] < cavity.half_y), depth - cavity.depth, 0.0)
    if (floor > 0.0).any():
        pen[:] = np.maximum(floor, 0.0)
        normals[:] = 0.0
        normals[:, 2] = 1.0
        forces += _penalty(law, pen, normals, v)
    return forces


def _penalty(law: ContactLaw, pen: np.ndarray, normals: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Spring-damper along the normal (never pulling) plus regularised Coulomb friction."""
    vn = np.einsum("ij,ij->i", v, normals)
    fn = np.where(pen > 0.0, np.maximum(law.stiffness * pen - law.damping * vn, 0.0), 0.0)
    vt = v - vn[:, None] * normals
    speed = np.sqrt(np.einsum("ij,ij->i", vt, vt) + law.slip_velocity ** 2)
    return fn[:, None] * normals - (law.friction * fn / speed)[:, None] * vt


def _may_touch(cavity: Cavity, corners: np.ndarray) -> bool:
    """False when the box (its corners, in F) surely touches nothing. Every sample point lies on
    the box, inside its corners' convex hull, so a convex set holding all 8 corners (with CLEAR
    of margin for rounding) holds every sample point too. Free of a side's wedge: all corners
    within the wall's slab |u| < half, or all inside the chamfer's funnel |u| + depth < half +
    chamfer; free of the floor: all corners above it or to one side of its footprint."""
    x, y, z = corners.T.tolist()
    outer_x, outer_y = cavity.half_x + cavity.chamfer + cavity.rim, cavity.half_y + cavity.chamfer + cavity.rim
    if min(x) > outer_x + CLEAR or max(x) < -outer_x - CLEAR or min(y) > outer_y + CLEAR or max(y) < -outer_y - CLEAR:
        return False              # wholly to one side of the body
    if min(z) > CLEAR:
        return False              # wholly above the opening plane
    if -min(z) >= cavity.depth - CLEAR and _over(x, cavity.half_x) and _over(y, cavity.half_y):
        return True               # may reach the floor
    # The wedges lie below the opening plane: only the long edges' part below z = CLEAR (hull of
    # the corners there and the edges' crossings of that plane) can reach them. A part
    # inserted within the clearance has its upper corners outside the slab and its lower ones
    # below the funnel, but that part inside the slab.
    x, y, z = _below_opening(x, y, z)
    return not (_free_of_wedge(x, z, cavity.half_x, cavity.chamfer) and _free_of_wedge(y, z, cavity.half_y, cavity.chamfer))


def _below_opening(x: list[float], y: list[float], z: list[float]) -> tuple[list[float], ...]:
    """Vertices of the long edges (corner i to corner i + 4) clipped to z <= CLEAR."""
    xs, ys, zs = [], [], []
    for a in range(4):
        b = a + 4
        za, zb = z[a], z[b]
        for k in (a, b):
            if z[k] <= CLEAR:
                xs.append(x[k]), ys.append(y[k]), zs.append(z[k])
        if (za <= CLEAR) != (zb <= CLEAR):
            s = (CLEAR - za) / (zb - za)
            xs.append(x[a] + s * (x[b] - x[a])), ys.append(y[a] + s * (y[b] - y[a])), zs.append(CLEAR)
    return xs, ys, zs


def _over(u: list[float], half: float) -> bool:
    """Not all of u to one side of the footprint |u| < half."""
    return min(u) < half + CLEAR and max(u) > -half - CLEAR


def _free_of_wedge(u: list[float], z: list[float], half: float, chamfer: float) -> bool:
    return (max(map(abs, u)) < half - CLEAR
            or max(abs(a) - b for a, b in zip(u, z)) < half + chamfer - CLEAR)


def may_touch(cavity: Cavity, box: MaleBox, F_T_M: np.ndarray) -> bool:
    """False when no point of the box posed at F_T_M can touch the cavity: it is clearly above
    the opening plane, wholly beside the body, or free inside the cavity (clear of its walls
    and floor). Scalars first: a box far beside the body (the next slot of a store) is told by
    its centre and half-diagonal, without its corners."""
    (_, _, r02, tx), (_, _, r12, ty), (r20, r21, r22, tz) = F_T_M[:3].tolist()
    reach = abs(r20) * box.half_x + abs(r21) * box.half_y
    if tz - reach > 1e-4 and r22 > 0.0:
        return False
    half = 0.5 * box.length
    if (abs(tx + half * r02) - box.radius > cavity.half_x + cavity.chamfer + cavity.rim + CLEAR
            or abs(ty + half * r12) - box.radius > cavity.half_y + cavity.chamfer + cavity.rim + CLEAR):
        return False
    return _may_touch(cavity, box.corners() @ F_T_M[:3, :3].T + F_T_M[:3, 3])


def box_contact(cavity: Cavity, box: MaleBox, law: ContactLaw, F_T_M: np.ndarray,
                F_T_M_rate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(points in F (16, 3), forces on the male part at those points in F (16, 3)) of the male
    box posed at F_T_M, moving at dF_T_M/dt."""
    pm = sample_points(box, F_T_M, cavity.chamfer)
    p = pm @ F_T_M[:3, :3].T + F_T_M[:3, 3]
    v = pm @ F_T_M_rate[:3, :3].T + F_T_M_rate[:3, 3]
    return p, cavity_forces(cavity, law, p, v)


def box_in_cavity(cavity: Cavity, box: MaleBox, law: ContactLaw, F_T_M: np.ndarray,
                  F_T_M_rate: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Contact of the male box posed at F_T_M (moving at dF_T_M/dt) in the cavity: box_contact,
    or None when may_touch says no point of the box can touch."""
    if not may_touch(cavity, box, F_T_M):
        return None
    return box_contact(cavity, box, law, F_T_M, F_T_M_rate)
