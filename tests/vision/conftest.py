import pytest

from spacearm.controller.vision.pipeline import VisionPipeline
from spacearm.firmware_sim.camera.simulator import CameraSimulator


@pytest.fixture(scope="module")
def pipeline() -> VisionPipeline:
    return VisionPipeline.from_configs()


@pytest.fixture
def camera() -> CameraSimulator:
    """Seeded: the same scene, lighting and noise on every run (renders ~0.3 s each)."""
    return CameraSimulator.from_configs(scene_seed=0, noise_seed=7)
