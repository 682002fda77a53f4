"""Sensor model of the GC1380H (Sony ICX285): shot + read noise, PRNU, 12-bit ADC, Mono8 out."""
from __future__ import annotations

import cv2
import numpy as np

from spacearm.base.vision.config import Sensor

NOISE_FRAMES = 3     # size of the drawn Gaussian field, in frames (each frame reads one window of it)
STRIP_ROWS = 128     # rows per band of the noise's passes (the band's planes fit in the cache)


class SensorModel:
    def __init__(self, sensor: Sensor, exposure_fill: float = 0.8, seed: int = 12345):
        """exposure_fill: fraction of full well reached by a white (albedo 1) surface under
        unit illumination (the fixed exposure of the approach phase)."""
        self.sensor = sensor
        self.exposure_fill = exposure_fill
        rng = np.random.default_rng(seed)          # PRNU is a fixed pattern of this sensor
        self.prnu = (1.0 + sensor.prnu * rng.standard_normal((sensor.height, sensor.width))).astype(np.float32)
        self.gain = sensor.full_well / (2 ** sensor.adc_bits - 1)     # e- per DN12
        # electrons per unit irradiance, per pixel (PRNU included): one multiply per frame
        self._electrons_per_unit = (self.prnu * np.float32(exposure_fill * sensor.full_well)).astype(np.float32)
        self._normal: np.ndarray | None = None     # standard normal field, drawn on the first noisy frame
        self._normal_rng: np.random.Generator | None = None

    def _noise_window(self, rng: np.random.Generator) -> np.ndarray:
        """A (H, W) window of standard normal noise. Drawing 1.4 M normals took 20 ms a frame,
        most of the frame's CPU: a field of NOISE_FRAMES frames is drawn once from the frame
        rng and each frame reads it at an offset drawn from that rng, so every frame's noise is
        independent Gaussian per pixel, a pixel's noise is uncorrelated from frame to frame
        (another offset puts another draw under it) and a seed still fixes every frame."""
        s = self.sensor
        n = s.height * s.width
        if self._normal is None or self._normal_rng is not rng:
            self._normal = rng.standard_normal(NOISE_FRAMES * n, dtype=np.float32)
            self._normal_rng = rng
        start = int(rng.integers(0, len(self._normal) - n + 1))
        return self._normal[start:start + n].reshape(s.height, s.width)

    def expose(self, irradiance: np.ndarray, rng: np.random.Generator | None,
               noise: bool = True) -> np.ndarray:
        """Relative irradiance (H, W) -> 8-bit frame. rng None or noise False: noiseless."""
        return self.expose_electrons(cv2.multiply(irradiance.astype(np.float32, copy=False), self._electrons_per_unit),
                                     rng, noise)

    @property
    def electrons_per_unit(self) -> np.ndarray:
        """(H, W) float32 electrons per unit irradiance (PRNU included): the renderer's `gain`."""
        return self._electrons_per_unit

    def expose_electrons(self, signal: np.ndarray, rng: np.random.Generator | None,
                         noise: bool = True) -> np.ndarray:
        """Photo-electrons (H, W) float32 (irradiance times electrons_per_unit, dark offset not
        included) -> 8-bit frame; `signal` is overwritten unless it is read-only."""
        s = self.sensor
        # 12-bit ADC (round, clip at 0 and full scale), then the top 8 bits: floor(rint(e / gain) / 2^k)
        # equals round(e / (gain 2^k) - (2^k - 1) / 2^(k+1)), in one saturating conversion
        # (electrons never go below 0 here: the black level is 10 read-noise sigmas above it)
        k = 2 ** (s.adc_bits - s.output_bits)
        scale = 1.0 / (self.gain * k)
        beta = s.dark_offset * scale - (k - 1) / (2.0 * k)
        if not (noise and rng is not None):
            return cv2.convertScaleAbs(signal, alpha=scale, beta=beta)
        normal = self._noise_window(rng)
        out = np.empty(signal.shape, np.uint8)
        sd = np.empty((STRIP_ROWS, signal.shape[1]), np.float32)
        kept = None if signal.flags.writeable else np.empty_like(sd)     # a read-only frame: a band copy
        # the dark offset is not added to the frame (one pass less): it is in the shot noise's
        # variance and in the ADC's offset. Done a band of rows at a time, so that the band's
        # intermediate planes stay in the cache (full-frame passes were memory-bound).
        for y in range(0, signal.shape[0], STRIP_ROWS):
            band = signal[y:y + STRIP_ROWS]
            rows = band.shape[0]
            dev = sd[:rows]
            if kept is not None:
                np.copyto(kept[:rows], band)
                band = kept[:rows]
            # Poisson shot ~ Gaussian here (NumPy's scalar add is ~3x OpenCV's)
            np.add(band, np.float32(s.dark_offset + s.read_noise ** 2), out=dev)
            cv2.sqrt(dev, dst=dev)
            cv2.accumulateProduct(dev, normal[y:y + STRIP_ROWS], band)                 # band += sd * n
            cv2.convertScaleAbs(band, dst=out[y:y + STRIP_ROWS], alpha=scale, beta=beta)
        return out
