"""Which detected blob is which characteristic circle (ORU paper Figure 13, "image point
recognition"), from the marker's known geometry.

The three plate circles form a scalene right triangle (c1 at the right angle, c1-c2 the long
leg, c1-c3 the short one) and the rod circle sits above a known point of the plate. For every
ordered triple of blobs taken as (c1, c2, c3) the affine map plate -> image is exact; it must
keep the handedness of the plate seen from its front, and with a weak-perspective camera it
predicts where the rod-top circle appears (see `hypotheses`). All triples x rod choices are
scored at once with numpy; the best few go to PnP, where the reprojection error decides. A prior pose (tracking) short-cuts this to a nearest-
neighbour match.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from itertools import permutations

import numpy as np

from spacearm.base.vision.marker import MarkerModel



@dataclass(frozen=True)
class Hypothesis:
    indices: tuple[int, int, int, int]   # candidate index for each marker point (model order)
    score: float                          # rod-foot mismatch in plate units (m); lower is better


@lru_cache(maxsize=64)
def _triples(n: int) -> np.ndarray:
    return np.array(list(permutations(range(n), 3)))


def _plate_basis(marker: MarkerModel) -> tuple[np.ndarray, np.ndarray]:
    """Rod foot in the affine coordinates of the plate triangle (c1; c2 - c1, c3 - c1)."""
    p = marker.points
    U = np.column_stack([p[1, :2] - p[0, :2], p[2, :2] - p[0, :2]])
    foot = np.linalg.solve(U, p[3, :2] - p[0, :2])
    return U, foot


# The weak-perspective miss of the true labelling grows as the marker's depth extent over its
# distance: up to 50 deg tilt it stays below ~0.19 m / depth x rod height (0.1-0.3 m, measured
# with tests/vision), so near the camera the tolerance widens to NEAR_TOLERANCE / depth.
NEAR_TOLERANCE = 0.25            # m


def hypotheses(marker: MarkerModel, centres: np.ndarray, max_keep: int = 64,
               tolerance: float = 0.6, depth_range: tuple[float, float] = (0.05, 3.0)) -> list[Hypothesis]:
    """Plausible labellings of the candidates, best first. centres: ideal normalised image
    coordinates. Each ordered triple (c1, c2, c3) gives the affine map of the plate; under a
    scaled-orthographic camera its two rows extend to orthogonal rows of equal length, which
    fixes the image of the marker's z axis up to sign (the classic weak-perspective two-fold
    ambiguity). The rod-top circle must then appear at foot + height * z_image; `score` is the
    miss in metres on the marker, accepted below max(tolerance, NEAR_TOLERANCE / depth) x rod
    height (perspective makes the weak-perspective prediction imperfect near the camera). The map's scale is 1/depth:
    triples implying a depth outside depth_range are dropped."""
    n = len(centres)
    if n < 4:
        return []
    U, foot = _plate_basis(marker)
    idx = _triples(n)                                                   # (P, 3)
    o = centres[idx[:, 0]]
    a = centres[idx[:, 1]] - o
    b = centres[idx[:, 2]] - o
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    # Seen from the plate's front the image (x right, y down) mirrors the plate's x-y
    # handedness, so the model's positive (c1, c2, c3) turn appears negative.
    sign_model = np.sign(np.linalg.det(U))
    keep = cross * sign_model < 0
    idx, o, a, b = idx[keep], o[keep], a[keep], b[keep]
    # affine map plate (m) -> image: M = [a b] U^-1; rows r1, r2 of M
    Uinv = np.linalg.inv(U)
    M = np.stack([a, b], axis=2) @ Uinv                                 # (P, 2, 2)
    r1, r2 = M[:, 0, :], M[:, 1, :]
    c = -(r1 * r2).sum(1)
    d = (r2 ** 2).sum(1) - (r1 ** 2).sum(1)
    w = (d + np.sqrt(d ** 2 + 4 * c ** 2)) / 2                          # z1^2
    z1 = np.sqrt(w)
    z2 = np.where(z1 > 1e-12, c / np.maximum(z1, 1e-12), np.sqrt(np.maximum(-d, 0.0)))
    scale = np.sqrt((r1 ** 2).sum(1) + w)                              # image units per metre
    h = float(marker.points[3, 2])
    foot_img = o + (M @ (marker.points[3, :2] - marker.points[0, :2]))  # (P, 2)
    zimg = np.stack([z1, z2], 1) * h
    pred = np.stack([foot_img + zimg, foot_img - zimg], 1)              # (P, 2, 2)
    miss = np.linalg.norm(pred[:, :, None, :] - centres[None, None, :, :], axis=3).min(1)  # (P, n)
    miss = miss / scale[:, None]
    miss[np.arange(len(idx))[:, None], idx] = np.inf
    # normalised coordinates: image units per metre = 1 / depth
    depth = 1.0 / np.maximum(scale, 1e-9)
    miss[(depth < depth_range[0]) | (depth > depth_range[1])] = np.inf
    accept = np.maximum(tolerance, NEAR_TOLERANCE / depth) * h
    p_i, r_i = np.nonzero(miss < accept[:, None])
    order = np.argsort(miss[p_i, r_i])[:max_keep]
    return [Hypothesis((int(idx[p, 0]), int(idx[p, 1]), int(idx[p, 2]), int(r)), float(miss[p, r]))
            for p, r in zip(p_i[order], r_i[order])]


def match_prior(predicted: np.ndarray, centres: np.ndarray, gate: float) -> Hypothesis | None:
    """Nearest candidate to each predicted marker point, if all four are unique and within
    `gate` (same units as the coordinates)."""
    if len(centres) < 4:
        return None
    d = np.linalg.norm(predicted[:, None, :] - centres[None, :, :], axis=2)
    pick = d.argmin(axis=1)
    if len(set(pick.tolist())) < 4 or (d[np.arange(4), pick] > gate).any():
        return None
    return Hypothesis(tuple(int(i) for i in pick), float(d[np.arange(4), pick].max()))


def plate_is_dark(image: np.ndarray, centres_px: np.ndarray, hyps: list[Hypothesis],
                  dark_ratio: float = 0.3, samples: int = 6) -> list[Hypothesis]:
    """Keep labellings whose plate triangle is black between its circles (the plate is matt
    black, clutter dots on separate patches have brighter wall between them): the image along
    the three edges (away from the circles) must stay below dark_ratio x the circles' level."""
    if not hyps:
        return []
    H, W = image.shape
    lim = np.array([W - 1, H - 1])
    tri = np.array([h.indices[:3] for h in hyps])                      # (K, 3)
    p = centres_px[tri]                                                  # (K, 3, 2)
    at = np.clip(np.rint(p).astype(int), 0, lim)
    level = image[at[..., 1], at[..., 0]].astype(float).mean(1)         # (K,)
    t = np.linspace(0.2, 0.8, samples)[None, :, None]
    pts = np.concatenate([p[:, i, None, :] + t * (p[:, j, None, :] - p[:, i, None, :])
                          for i, j in ((0, 1), (0, 2), (1, 2))], axis=1)  # (K, 3*samples, 2)
    pts = np.clip(np.rint(pts).astype(int), 0, lim)
    vals = image[pts[..., 1], pts[..., 0]].astype(float)
    ok = np.quantile(vals, 0.85, axis=1) < dark_ratio * level
    return [h for h, k in zip(hyps, ok) if k]
