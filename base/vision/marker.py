"""The stereo marker (three plate circles + one rod-top circle) and the ORU it sits on."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spacearm.base.vision.config import MarkerConfig


@dataclass(frozen=True)
class MarkerModel:
    names: tuple[str, ...]
    points: np.ndarray           # (4, 3) circle centres in the marker frame, m; plate circles first
    circle_radius: float         # m
    plate_size: tuple[float, float]
    plate_thickness: float
    rod_radius: float
    marker_T_oru: np.ndarray     # 4x4, seated ORU (scene frame: bottom face centre, z up)
    plate_albedo: float
    circle_albedo: float
    oru_albedo: float

    @classmethod
    def from_config(cls, cfg: MarkerConfig) -> "MarkerModel":
        # Plate circles first, rod last: the identification relies on that order.
        circles = sorted(cfg.circles, key=lambda c: c.xyz[2] > 0)
        return cls(tuple(c.name for c in circles), np.array([c.xyz for c in circles], float),
                   cfg.circle_diameter / 2, cfg.plate_size, cfg.plate_thickness,
                   cfg.rod_diameter / 2, cfg.marker_T_oru.matrix(),
                   cfg.plate_albedo, cfg.circle_albedo, cfg.oru_albedo)

    @property
    def rod_index(self) -> int:
        return 3

    @property
    def span(self) -> float:
        """Largest distance between two circle centres, m."""
        d = self.points[:, None, :] - self.points[None, :, :]
        return float(np.sqrt((d ** 2).sum(-1)).max())
