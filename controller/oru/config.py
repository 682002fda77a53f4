"""Parameters of the ORU changeout task flow (configs/oru/changeout.toml)."""
from __future__ import annotations

from pathlib import Path

from pydantic import Field

from spacearm.base.paths import CONFIGS
from spacearm.base.config.loader import StrictModel, load_toml_model

DEFAULT_CHANGEOUT = CONFIGS / "oru" / "changeout.toml"


class StageConfig(StrictModel):
    name: str = Field(min_length=1, max_length=64)
    store: str = Field(min_length=1, max_length=64, description="store the stage picks from / places into")


class MotionConfig(StrictModel):
    view_height: float = Field(default=0.15, gt=0.0, le=1.0, description="m")
    contact_gap: float = Field(default=0.010, gt=0.0, le=0.1, description="m")
    approach_gap: float = Field(default=0.075, gt=0.0, le=0.3, description="m, gap at the end of the closed-loop approach")
    extract_clearance: float = Field(default=0.02, gt=0.0, le=0.2, description="m")
    withdraw_clearance: float = Field(default=0.02, gt=0.0, le=0.2, description="m")
    speed: float = Field(default=1.0, gt=0.0, le=1.0)


class EndEffectorConfig(StrictModel):
    sensor_offset: float = Field(default=0.20, ge=0.0, le=2.0, description="m")
    mass: float = Field(default=3.0, ge=0.0, le=100.0, description="kg")
    centroid: tuple[float, float, float] = (0.0, 0.0, 0.08)
    clamp_timeout: float = Field(default=12.0, gt=0.0, le=120.0, description="s")
    release_timeout: float = Field(default=12.0, gt=0.0, le=120.0, description="s")
    latch_wait: float = Field(default=1.5, gt=0.0, le=60.0, description="s")


class ContactConfig(StrictModel):
    capture_stiffness: tuple[float, float, float, float, float, float] = (0.0, 0.0, 1000.0, 0.0, 0.0, 0.0)
    seat_tolerance: float = Field(default=0.006, gt=0.0, le=0.05, description="m")


class VisionRetryConfig(StrictModel):
    """What the flow does when the closed-loop approach loses its camera (marker lost, camera
    stopped, stale frames): hold, retry a bounded number of times, then pause with the reason."""
    approach_retries: int = Field(default=2, ge=0, le=20, description="new approach attempts before pausing")
    retry_hold: float = Field(default=1.0, ge=0.0, le=60.0, description="s held still before each retry")


class ChangeoutConfig(StrictModel):
    stages: list[StageConfig] = Field(min_length=2, max_length=8)
    motion: MotionConfig = MotionConfig()
    vision: VisionRetryConfig = VisionRetryConfig()
    end_effector: EndEffectorConfig = EndEffectorConfig()
    contact: ContactConfig = ContactConfig()


def load_changeout(path: str | Path = DEFAULT_CHANGEOUT) -> ChangeoutConfig:
    return load_toml_model(path, ChangeoutConfig)
