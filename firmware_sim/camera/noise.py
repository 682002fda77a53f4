"""Sensor model of the GC1380H (Sony ICX285): shot + read noise, PRNU, 12-bit ADC, Mono8 out."""
from __future__ import annotations

import numpy as np

from spacearm.base.vision.config import Sensor


class SensorModel:
    def __init__(self, sensor: Sensor, exposure_fill: float = 0.8, seed: int = 12345):
        """exposure_fill: fraction of full well reached by a white (albedo 1) surface under
        unit illumination (the fixed exposure of the approach phase)."""
        self.sensor = sensor
        self.exposure_fill = exposure_fill
        rng = np.random.default_rng(seed)          # PRNU is a fixed pattern of this sensor
        self.prnu = (1.0 + sensor.prnu * rng.standard_normal((sensor.height, sensor.width))).astype(np.float32)
        self.gain = sensor.full_well / (2 ** sensor.adc_bits - 1)     # e- per DN12

    def expose(self, irradiance: np.ndarray, rng: np.random.Generator | None,
               noise: bool = True) -> np.ndarray:
        """Relative irradiance (H, W) -> 8-bit frame. rng None or noise False: noiseless."""
        s = self.sensor
        electrons = irradiance * (self.exposure_fill * s.full_well) * self.prnu + s.dark_offset
        if noise and rng is not None:
            sd = np.sqrt(electrons + s.read_noise ** 2)           # Poisson shot ~ Gaussian here
            electrons = electrons + sd * rng.standard_normal(electrons.shape, dtype=np.float32)
        dn12 = np.clip(np.rint(electrons / self.gain), 0, 2 ** s.adc_bits - 1)
        shift = s.adc_bits - s.output_bits
        return (dn12.astype(np.uint16) >> shift).astype(np.uint8)
