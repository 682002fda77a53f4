"""Camera simulator: the eye-in-hand camera's frames from the plant's true poses."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from spacearm.base.spatial import inv_transform
from spacearm.base.vision.camera import CameraModel
from spacearm.base.vision.config import CameraConfig, MarkerConfig, MountConfig, load_camera, load_marker, load_mount
from spacearm.base.vision.frames import Frame
from spacearm.base.vision.marker import MarkerModel
from spacearm.firmware_sim.camera.noise import SensorModel
from spacearm.firmware_sim.camera.renderer import FlatLayer, Renderer
from spacearm.firmware_sim.camera.scene import Scene


@dataclass
class CameraSimulator:
    camera: CameraModel
    renderer: Renderer
    sensor: SensorModel
    scene: Scene
    end_T_camera: np.ndarray
    rng: np.random.Generator
    seq: int = 0

    @classmethod
    def from_configs(cls, camera: CameraConfig | None = None, marker: MarkerConfig | None = None,
                     mount: MountConfig | None = None, scene_seed: int = 0,
                     noise_seed: int | None = None) -> "CameraSimulator":
        camera = camera or load_camera()
        marker_model = MarkerModel.from_config(marker or load_marker())
        mount = mount or load_mount()
        cam = CameraModel.from_config(camera)
        return cls(cam, Renderer(cam, camera.optics), SensorModel(camera.sensor),
                   Scene.cluttered(marker_model, seed=scene_seed), mount.end_T_camera.matrix(),
                   np.random.default_rng(noise_seed))

    def render(self, camera_T_marker: np.ndarray, timestamp: float = 0.0, noise: bool = True) -> Frame:
        """A frame seen from the given true camera_T_marker (4x4)."""
        image = self.image(camera_T_marker, noise=noise)
        self.seq += 1
        return Frame(timestamp=timestamp, seq=self.seq, image=image,
                     true_camera_T_marker=np.asarray(camera_T_marker, float).copy())

    def image(self, camera_T_marker: np.ndarray, flat_layers: Sequence[FlatLayer] = (), noise: bool = True) -> np.ndarray:
        """The 8-bit image seen from camera_T_marker with `flat_layers` (a calibration board) in view."""
        exposure = self.sensor.exposure(self.rng, noise)
        electrons = self.renderer.render(self.scene, camera_T_marker, flat_layers, gain=self.sensor.electrons_per_unit,
                                         exposure=exposure)
        if electrons is not None:           # an image the renderer keeps (an arm at rest)
            exposure.whole(electrons)
        return exposure.frame

    def render_from_plant(self, base_T_end: np.ndarray, base_T_marker: np.ndarray,
                          timestamp: float = 0.0) -> Frame:
        """A frame from the plant's true end pose and the marker's pose (both in the base)."""
        base_T_camera = base_T_end @ self.end_T_camera
        return self.render(inv_transform(base_T_camera) @ base_T_marker, timestamp)
