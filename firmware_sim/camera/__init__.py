"""Simulated eye-in-hand camera: scene (marker, ORU, clutter, lighting), renderer, sensor noise.

    sim = CameraSimulator.from_configs(scene_seed=0, noise_seed=1)
    frame = sim.render(camera_T_marker)                     # Frame(timestamp, seq, image, truth)
    frame = sim.render_from_plant(base_T_end, base_T_marker)
"""
from spacearm.firmware_sim.camera.noise import SensorModel
from spacearm.firmware_sim.camera.renderer import Renderer
from spacearm.firmware_sim.camera.scene import Lighting, OruShape, Scene
from spacearm.firmware_sim.camera.simulator import CameraSimulator

__all__ = ["CameraSimulator", "Renderer", "Scene", "Lighting", "OruShape", "SensorModel"]
