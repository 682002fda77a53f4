"""The camera's render process (firmware_sim/camera/render_process.py) renders the same frames
as the in-process renderer: same seeds, same noise stream, same stores shown with an ORU."""
from __future__ import annotations

import numpy as np

from spacearm.base.config.scene import load_scene
from spacearm.base.vision.config import load_camera
from spacearm.base.vision.frames import LocalFrameSource, ShmFrameRing
from spacearm.firmware_sim.camera.service import CameraService


def camera_pose(service: CameraService, store: str, distance: float) -> np.ndarray:
    """Camera `distance` m in front of a store's marker, looking at it."""
    site = next(s for s in service.sites if s.store == store)
    flip = np.diag([1.0, -1.0, -1.0, 1.0])               # camera z towards the marker
    flip[2, 3] = distance
    return site.base_T_marker @ flip


def test_render_process_gives_the_frames_of_the_in_process_renderer():
    cam = load_camera()
    scene = load_scene()
    local = CameraService.from_files(None, LocalFrameSource(), scene)
    ring = ShmFrameRing.create(cam.sensor.width, cam.sensor.height)
    remote = CameraService.from_files(None, ring, scene).use_render_process()
    try:
        stores = sorted(s.store for s in local.sites)
        for k, (store, stocked) in enumerate([(stores[0], frozenset()), (stores[0], frozenset(stores)),
                                              (stores[-1], frozenset(stores[:1]))]):
            pose = camera_pose(local, store, 0.25 + 0.05 * k)
            local._render(0.1 * k, k + 1, pose, stocked)
            remote._render(0.1 * k, k + 1, pose, stocked)
            a, b = local.sink.latest(), ring.latest()
            assert (a.sync, a.timestamp) == (b.sync, b.timestamp) == (k + 1, 0.1 * k)
            assert np.array_equal(a.image, b.image) and np.allclose(a.true_camera_T_marker, b.true_camera_T_marker)
        assert remote.frames == 3 and remote.errors == 0
    finally:
        remote.stop()
        ring.close()
