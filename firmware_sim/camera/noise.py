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
        exposure = self.exposure(rng, noise)
        exposure.whole(signal)
        return exposure.frame

    def exposure(self, rng: np.random.Generator | None, noise: bool = True) -> "Exposure":
        """One frame's exposure, its noise drawn from `rng` (rng None or noise False: noiseless),
        to be given the frame's electrons a band of rows at a time (Renderer.render(exposure=...):
        each band while it is still in the cache) or whole."""
        return Exposure(self, self._noise_window(rng) if noise and rng is not None else None)


class Exposure:
    """A frame's photo-electrons -> its 8-bit frame (`frame`), band by band, in place."""

    def __init__(self, model: SensorModel, normal: np.ndarray | None):
        s = model.sensor
        # 12-bit ADC (round, clip at 0 and full scale), then the top 8 bits: floor(rint(e / gain) / 2^k)
        # equals round(e / (gain 2^k) - (2^k - 1) / 2^(k+1)), in one saturating conversion
        # (electrons never go below 0 here: the black level is 10 read-noise sigmas above it)
        k = 2 ** (s.adc_bits - s.output_bits)
        self._scale = 1.0 / (model.gain * k)
        self._beta = s.dark_offset * self._scale - (k - 1) / (2.0 * k)
        # the dark offset is not added to the frame (one pass less): it is in the shot noise's
        # variance and in the ADC's offset
        self._variance_floor = np.float32(s.dark_offset + s.read_noise ** 2)
        self._normal = normal
        self.frame = np.empty((s.height, s.width), np.uint8)
        self._sd = np.empty((STRIP_ROWS, s.width), np.float32) if normal is not None else None

    def band(self, electrons: np.ndarray, y: int) -> None:
        """The frame's rows y:y+len(electrons) from their electrons (overwritten with the noisy
        electrons)."""
        rows = electrons.shape[0]
        out = self.frame[y:y + rows]
        if self._normal is None:
            cv2.convertScaleAbs(electrons, dst=out, alpha=self._scale, beta=self._beta)
            return
        if self._sd.shape[0] < rows:
            self._sd = np.empty((rows, self._sd.shape[1]), np.float32)
        dev = self._sd[:rows]
        # Poisson shot ~ Gaussian here (NumPy's scalar add is ~3x OpenCV's)
        np.add(electrons, self._variance_floor, out=dev)
        cv2.sqrt(dev, dst=dev)
        cv2.accumulateProduct(dev, self._normal[y:y + rows], electrons)                # band += sd * n
        cv2.convertScaleAbs(electrons, dst=out, alpha=self._scale, beta=self._beta)

    def whole(self, signal: np.ndarray) -> None:
        """The whole frame from its electrons (H, W), a band of rows at a time so that the band's
        intermediate planes stay in the cache (full-frame passes were memory-bound); `signal` is
        overwritten unless it is read-only (then each band is copied first)."""
        kept = None if signal.flags.writeable or self._normal is None else np.empty_like(self._sd)
        for y in range(0, signal.shape[0], STRIP_ROWS):
            band = signal[y:y + STRIP_ROWS]
            if kept is not None:
                band = kept[:band.shape[0]]
                np.copyto(band, signal[y:y + STRIP_ROWS])
            self.band(band, y)
