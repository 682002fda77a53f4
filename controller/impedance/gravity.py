"""Gravity compensation of the measured wrench (ORU paper eqs. 13-14).

F_contact = F_sensor - [R_f g_m ; r_c x R_f g_m] with g_m = (0, 0, -m g) in the base frame,
R_f = sensor_R_base (from forward kinematics and the assembly's end_T_sensor, eq. 13), m and
r_c the mass and centroid (sensor frame) of the end effector, or of the end effector plus
the captured ORU. The sensor convention is the wrench ON the end effector, so the reading
contains +gravity and the contact wrench pushes the tool the way it must give.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from spacearm.base.spatial import cross3


@dataclass(frozen=True)
class GravityModel:
    mass: float                   # kg
    centroid: np.ndarray          # m, sensor frame
    g: float = 9.81

    def wrench(self, base_R_sensor: np.ndarray) -> np.ndarray:
        """Gravity wrench the sensor feels (sensor frame, about its origin)."""
        f = base_R_sensor.T @ np.array([0.0, 0.0, -self.mass * self.g])
        return np.concatenate([f, cross3(np.asarray(self.centroid, float).tolist(), f.tolist())])

    def compensate(self, measured: np.ndarray, base_R_sensor: np.ndarray) -> np.ndarray:
        return np.asarray(measured, float) - self.wrench(base_R_sensor)

    def with_payload(self, mass: float, centroid: np.ndarray) -> "GravityModel":
        """End effector plus a captured payload: combined mass and centroid."""
        total = self.mass + mass
        c = (self.mass * np.asarray(self.centroid) + mass * np.asarray(centroid)) / total
        return GravityModel(total, c, self.g)
