"""What the eye-in-hand camera looks at: marker + ORU, a cluttered background wall, lighting.

Everything is expressed in the marker frame (see configs/vision/marker.toml). The scene is
deterministic for a given seed so that noisy renders of one pose differ only by noise.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from spacearm.base.vision.marker import MarkerModel


@dataclass(frozen=True)
class Polygon:
    """Planar polygon on the background wall: (N, 3) vertices in the marker frame, albedo."""
    vertices: np.ndarray
    albedo: float


@dataclass(frozen=True)
class Lighting:
    """Uneven lighting as a smooth multiplicative field over the image plus Lambert shading.

    gradient: relative change of illumination across the image width along `direction`;
    a hot spot of relative amplitude `spot_gain` and width `spot_sigma` (fraction of the
    image width) at `spot_centre` (fractions of width/height); `sun` is the direction
    towards the main light in the marker frame (faces are shaded by max(n.l, 0)).
    """
    level: float = 1.0
    gradient: float = 0.3
    direction: float = 0.5                   # rad, in the image plane
    spot_gain: float = 0.4
    spot_sigma: float = 0.25
    spot_centre: tuple[float, float] = (0.3, 0.4)
    sun: tuple[float, float, float] = (0.3, -0.4, 0.87)
    ambient: float = 0.35


@dataclass(frozen=True)
class OruShape:
    """A seated ORU box and its adapter (scene file [geometry]), m."""
    size: tuple[float, float, float]
    adapter: tuple[float, float, float]


@dataclass
class Scene:
    marker: MarkerModel
    wall_depth: float = 0.40                 # m, background wall behind the marker plate
    wall_albedo: float = 0.30
    clutter: list[Polygon] = field(default_factory=list)
    lighting: Lighting = field(default_factory=Lighting)
    oru: OruShape | None = OruShape((0.12, 0.08, 0.10), (0.04, 0.02, 0.03))   # None: empty slot

    @classmethod
    def cluttered(cls, marker: MarkerModel, seed: int = 0, n_shapes: int = 140,
                  n_dots: int = 60, extent: float = 1.2) -> "Scene":
        """A wall with random polygons, discs and bright dots (4-8 mm, some on dark patches,
        the worst distractors for the circle detector) over +-extent m."""
        rng = np.random.default_rng(seed)
        z = -0.40
        shapes: list[Polygon] = []
        for _ in range(n_shapes):
            c = rng.uniform(-extent, extent, 2)
            size = rng.uniform(0.02, 0.25)
            kind = rng.integers(3)
            if kind == 0:                    # rectangle, random orientation
                a = rng.uniform(0, np.pi)
                w, h = size, size * rng.uniform(0.2, 1.0)
                corners = np.array([[-w, -h], [w, -h], [w, h], [-w, h]]) / 2
                R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
                xy = corners @ R.T + c
            elif kind == 1:                  # triangle
                xy = c + rng.uniform(-size, size, (3, 2)) / 2
            else:                            # disc / ellipse
                t = np.linspace(0, 2 * np.pi, 48, endpoint=False)
                xy = c + np.stack([np.cos(t), rng.uniform(0.4, 1.0) * np.sin(t)], 1) * size / 2
            shapes.append(Polygon(_on_plane(xy, z), float(rng.uniform(0.02, 0.95))))
        t = np.linspace(0, 2 * np.pi, 32, endpoint=False)
        unit = np.stack([np.cos(t), np.sin(t)], 1)
        for i in range(n_dots):
            c = rng.uniform(-extent, extent, 2)
            if i % 3 == 0:                   # dark patch with a white dot: looks like a marker circle
                shapes.append(Polygon(_on_plane(c + unit * 0.012, z), 0.04))
            shapes.append(Polygon(_on_plane(c + unit * rng.uniform(0.002, 0.004), z),
                                  float(rng.uniform(0.7, 0.95))))
        light = Lighting(level=float(rng.uniform(0.7, 1.0)), gradient=float(rng.uniform(0.1, 0.5)),
                         direction=float(rng.uniform(0, 2 * np.pi)), spot_gain=float(rng.uniform(0.1, 0.6)),
                         spot_sigma=float(rng.uniform(0.15, 0.4)),
                         spot_centre=(float(rng.uniform(0.1, 0.9)), float(rng.uniform(0.1, 0.9))))
        return cls(marker, wall_depth=-z, clutter=shapes, lighting=light)


def _on_plane(xy: np.ndarray, z: float) -> np.ndarray:
    return np.column_stack([xy, np.full(len(xy), z)])
