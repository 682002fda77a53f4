"""The simulated camera's trigger modes (firmware_sim/camera/service.py, base/vision/frames.py):
free run exposes at its rate, an idle lockstep camera not at all unless another reader asks for
one exposure at or after a SYNC, an acquiring lockstep camera at every due SYNC, announced."""
from __future__ import annotations

import numpy as np

from spacearm.base.vision.frames import CameraTrigger, LocalFrameSource
from spacearm.firmware_sim.camera.service import CameraService


class StillPlant:
    time = 0.0

    def tool_pose(self) -> np.ndarray:
        return np.eye(4)


def exposures(service: CameraService, plant: StillPlant, syncs: range) -> list[int]:
    taken = []
    for sync in syncs:
        plant.time = sync * 0.02
        before = len(service._pending)
        service.on_sync(sync)
        if len(service._pending) > before:
            taken.append(sync)
            service._pending.clear()          # as if rendered (no render thread here)
    return taken


def test_trigger_modes_decide_which_syncs_expose():
    plant, sink = StillPlant(), LocalFrameSource()
    service = CameraService.from_files(plant, sink, frame_rate=25.0)      # every other 20 ms SYNC
    sink.set_trigger(CameraTrigger.LOCKSTEP_IDLE)
    assert exposures(service, plant, range(1, 20)) == []
    sink.request_exposure(23)
    assert exposures(service, plant, range(20, 30)) == [23] and sink.exposure_sync() == 23
    sink.set_trigger(CameraTrigger.LOCKSTEP)
    assert exposures(service, plant, range(30, 36)) == [30, 32, 34] and sink.exposure_sync() == 34
    sink.set_trigger(CameraTrigger.FREE_RUN)
    assert exposures(service, plant, range(36, 42)) == [36, 38, 40]
    assert sink.exposure_sync() == 34                                    # free run announces nothing
