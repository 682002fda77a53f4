"""Schema of the vision files (configs/vision/*.toml): camera, mount, marker, pipeline.

All quantities are SI (m, rad). Pixel quantities are in px. The TOML files quote the
data-sheet / paper figures in comments.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from pydantic import Field, model_validator

from spacearm.base.paths import CONFIGS
from spacearm.base.config.loader import StrictModel, load_toml_model
from spacearm.base.spatial import xyz_rpy_to_transform

CONFIG_DIR = CONFIGS / "vision"


class Pose(StrictModel):
    """Rigid transform parent_T_child = Trans(xyz) * Rz(yaw) Ry(pitch) Rx(roll)."""
    xyz: tuple[float, float, float] = Field(description="m")
    rpy: tuple[float, float, float] = Field(description="rad")

    @model_validator(mode="after")
    def _bounded(self) -> "Pose":
        if max(abs(v) for v in self.xyz) > 10.0:
            raise ValueError(f"xyz {self.xyz} beyond 10 m: mm given instead of m?")
        if max(abs(v) for v in self.rpy) > 2 * math.pi:
            raise ValueError(f"rpy {self.rpy} beyond 2 pi: degrees given instead of rad?")
        return self

    def matrix(self) -> np.ndarray:
        return xyz_rpy_to_transform(self.xyz, self.rpy)


# ----------------------------------------------------------------------------- camera
class Sensor(StrictModel):
    width: int = Field(ge=16, le=10000, description="px")
    height: int = Field(ge=16, le=10000, description="px")
    pixel_size: float = Field(gt=0.5e-6, lt=50e-6, description="m")
    full_well: float = Field(gt=100.0, le=1e6, description="e-")
    read_noise: float = Field(ge=0.0, le=1000.0, description="e- rms")
    adc_bits: int = Field(ge=8, le=16)
    output_bits: int = Field(ge=8, le=8, description="frames are 8-bit mono")
    prnu: float = Field(ge=0.0, le=0.1, description="pixel response non-uniformity, rms fraction")
    dark_offset: float = Field(ge=0.0, le=1000.0, description="e-")


class Intrinsics(StrictModel):
    fx: float = Field(gt=10.0, lt=1e5, description="px")
    fy: float = Field(gt=10.0, lt=1e5, description="px")
    cx: float = Field(ge=0.0, lt=1e4, description="px")
    cy: float = Field(ge=0.0, lt=1e4, description="px")
    # OpenCV order k1, k2, p1, p2, k3
    distortion: tuple[float, float, float, float, float]


class Optics(StrictModel):
    focal_length: float = Field(gt=1e-3, lt=0.5, description="m")
    f_number: float = Field(ge=1.0, le=32.0)
    focus_distance: float = Field(gt=0.05, le=100.0, description="m")
    wavelength: float = Field(gt=300e-9, lt=1100e-9, description="m")
    vignetting: float = Field(ge=0.0, le=1.0, description="relative fall-off at the image corner")


class CameraConfig(StrictModel):
    name: str
    sensor: Sensor
    intrinsics: Intrinsics
    optics: Optics
    frame_rate: float = Field(gt=0.0, le=1000.0, description="Hz")

    @model_validator(mode="after")
    def _centre_inside(self) -> "CameraConfig":
        i, s = self.intrinsics, self.sensor
        if not (0 <= i.cx < s.width and 0 <= i.cy < s.height):
            raise ValueError(f"principal point ({i.cx}, {i.cy}) outside the {s.width}x{s.height} sensor")
        return self


class MountConfig(StrictModel):
    end_T_camera: Pose


# ----------------------------------------------------------------------------- marker
class Circle(StrictModel):
    name: str
    xyz: tuple[float, float, float] = Field(description="centre in the marker frame, m")


class MarkerConfig(StrictModel):
    plate_size: tuple[float, float] = Field(description="m (x, y)")
    plate_thickness: float = Field(gt=0.0, lt=0.05, description="m")
    circle_diameter: float = Field(gt=0.0, lt=0.05, description="m")
    circles: tuple[Circle, Circle, Circle, Circle]
    rod_diameter: float = Field(gt=0.0, lt=0.05, description="m")
    plate_albedo: float = Field(ge=0.0, le=1.0)
    circle_albedo: float = Field(ge=0.0, le=1.0)
    marker_T_oru: Pose = Field(description="marker frame -> frame of an ORU seated in the slot the "
                                           "marker belongs to (scene convention: bottom face centre, z up)")
    oru_albedo: float = Field(ge=0.0, le=1.0)

    @model_validator(mode="after")
    def _geometry(self) -> "MarkerConfig":
        coplanar = [c for c in self.circles if abs(c.xyz[2]) < 1e-9]
        if len(coplanar) != 3:
            raise ValueError("exactly three circles must lie on the plate (z = 0), one on the rod (z > 0)")
        rod = [c for c in self.circles if c.xyz[2] > 0]
        if len(rod) != 1:
            raise ValueError("the fourth circle must be on top of the rod (z > 0)")
        hx, hy = self.plate_size[0] / 2, self.plate_size[1] / 2
        for c in self.circles:
            if abs(c.xyz[0]) > hx or abs(c.xyz[1]) > hy:
                raise ValueError(f"circle {c.name} at {c.xyz} lies outside the plate")
        if max(self.plate_size) > 2.0:
            raise ValueError("plate sizes beyond 2 m: mm given instead of m?")
        return self


# ----------------------------------------------------------------------------- pipeline
class PipelineConfig(StrictModel):
    gaussian_sigma: float = Field(ge=0.0, le=5.0, description="px, denoising before thresholding")
    search_scale: int = Field(ge=1, le=4, description="down-sampling factor of the full-frame search")
    background_window: int = Field(ge=3, le=301, description="px (search scale), local mean B window")
    threshold_s: float = Field(gt=0.0, le=50.0, description="T = B + s*sigma")
    min_contrast: float = Field(gt=0.0, le=255.0, description="DN, blob peak above local background")
    dark_surround_ratio: float = Field(gt=0.0, le=1.0, description="surround / blob-peak ratio a plate circle must stay below")
    min_diameter_px: float = Field(gt=0.0, le=100.0, description="px (full res); smaller blobs count as too far")
    max_diameter_px: float = Field(gt=1.0, le=1000.0, description="px (full res)")
    max_candidates: int = Field(ge=4, le=40)
    canny_low: float = Field(gt=0.0, le=1000.0)
    canny_high: float = Field(gt=0.0, le=1000.0)
    max_reprojection_px: float = Field(gt=0.0, le=20.0, description="px, rms gate on the final pose")
    ambiguity_ratio: float = Field(ge=1.0, le=100.0, description="second-best / best reprojection error must exceed this")
    max_distance: float = Field(gt=0.0, le=20.0, description="m, beyond this the pose is 'too_far'")
    min_distance: float = Field(gt=0.0, le=5.0, description="m")
    border_margin_px: float = Field(ge=0.0, le=200.0, description="px, circles closer to the border are out of view")
    solver: str = Field(pattern="^(sqpnp|ap3p|iterative|epnp)$", description="IPPE needs 4 coplanar points; the marker has 3")
    refine_lm: bool
    ellipse_centre_correction: bool
    track_roi: bool
    opencv_threads: int = Field(default=1, ge=0, le=16, description="cv2.setNumThreads for the process "
                                "(0 = OpenCV's default); bench_vision measures 1 vs 2")
    check_px: float = Field(default=0.5, gt=0.0, le=20.0, description="px rms: a refined pose worse than this "
                            "is solved again with the second solver (sqpnp <-> ap3p)")

    @model_validator(mode="after")
    def _order(self) -> "PipelineConfig":
        if self.canny_low >= self.canny_high:
            raise ValueError("canny_low must be below canny_high")
        if self.min_diameter_px >= self.max_diameter_px:
            raise ValueError("min_diameter_px must be below max_diameter_px")
        if self.background_window % 2 == 0:
            raise ValueError("background_window must be odd")
        return self


def load_camera(path: str | Path = CONFIG_DIR / "camera_gc1380h.toml") -> CameraConfig:
    return load_toml_model(path, CameraConfig)


def load_mount(path: str | Path = CONFIG_DIR / "mount.toml") -> MountConfig:
    return load_toml_model(path, MountConfig)


def load_marker(path: str | Path = CONFIG_DIR / "marker.toml") -> MarkerConfig:
    return load_toml_model(path, MarkerConfig)


def load_pipeline(path: str | Path = CONFIG_DIR / "pipeline.toml") -> PipelineConfig:
    return load_toml_model(path, PipelineConfig)
