"""The eye-in-hand camera inside the simulator process: frames from the plant's true poses.

An exposure falls due every 1/frame_rate s of *plant* time: at that SYNC the camera snapshots
the true camera pose (plant.tool_pose() @ end_T_camera, true geometry with the plant file's
errors) and the true marker poses (scene slot pose @ true_offset @ marker placement). Frames
carry the plant time and the SYNC number of the exposure. The sink's trigger mode (set by the
controller, base/vision/frames.py CameraTrigger) decides when the frame is rendered:

- free run (real time): a thread renders and publishes outside the SYNC handler, so rendering
  (50-200 ms per frame on this machine) never delays the nodes' answers. Rendering is slower
  than 30 Hz here; the effective rate is what the renderer manages (frames are dropped, never
  queued), so which exposures become frames depends on the machine's load.
- lockstep: every due exposure is queued for the render thread and its SYNC number announced
  in the sink before the nodes answer; the controller's cycle for that SYNC waits until the
  frame is published (controller/vision/lockstep.py). The frames a run sees are fixed by plant
  time and the noise seed, not by the machine. While the controller does not acquire
  (LOCKSTEP_IDLE) nothing is rendered: lockstep outside the approaches runs at full speed.

    service = CameraService.from_files(plant, sink)      # sink: ShmFrameRing or LocalFrameSource
    service.show_board(load_board())                     # optional: calibration checkerboard in the cell
    service.start(); ...; service.stop()

With a board (`spacearm sim --camera NAME --board FILE`) every frame also shows the
checkerboard at its true pose (nominal pose @ true_offset of the board file), drawn with the
same lens distortion, defocus, lighting and sensor noise as the marker scene; frames still
carry the marker truth only.
"""
from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spacearm.base.config.scene import DEFAULT_SCENE, SceneConfig, load_scene
from spacearm.base.spatial import inv_transform
from spacearm.base.vision.frames import CameraTrigger
from spacearm.firmware_sim.calibration_board import board_patch
from spacearm.firmware_sim.camera.renderer import FlatLayer
from spacearm.firmware_sim.camera.scene import OruShape
from spacearm.firmware_sim.camera.simulator import CameraSimulator
from spacearm.base.runtime.priority import use_normal


@dataclass(frozen=True)
class MarkerSite:
    store: str
    base_T_marker: np.ndarray        # true pose
    holds_oru: bool


def marker_sites(scene: SceneConfig, marker_T_oru: np.ndarray) -> list[MarkerSite]:
    """True marker pose at every store: base_T_slot(nominal) @ true_offset @ slot_T_oru @ oru_T_marker."""
    g = scene.geometry
    out = []
    for s in scene.stores:
        base_T_slot = s.pose.matrix() @ s.true_offset.matrix()
        out.append(MarkerSite(s.name, base_T_slot @ g.slot_T_oru() @ inv_transform(marker_T_oru), s.holds is not None))
    return out


class CameraService:
    def __init__(self, plant, sink, camera: CameraSimulator, scene: SceneConfig,
                 frame_rate: float | None = None, render_noise: bool = True):
        self.plant = plant
        self.sink = sink
        self.camera = camera
        self.sites = marker_sites(scene, camera.scene.marker.marker_T_oru)
        g = scene.geometry
        self._oru = OruShape(tuple(g.oru_size), tuple(g.adapter_size))
        self.period = 1.0 / (frame_rate or 30.0)
        self.render_noise = render_noise
        self.min_gap = 0.03                  # s of wall time between renders
        self._next_exposure = 0.0
        self._pending: deque[tuple] = deque()      # exposures taken, not yet rendered (free run: <= 1)
        self._wake = threading.Condition()
        self._stop = False
        self._thread: threading.Thread | None = None
        self.frames = 0
        self.errors = 0
        self.board = None                    # BoardConfig once show_board() was called
        self.base_T_board = None             # its true pose
        self._board_seen: tuple | None = None    # (camera_T_board bytes, layers): an arm at rest keeps them
        self.scene_config = scene
        self.seeds: tuple[int, int | None] | None = None      # (scene, noise), set by from_files
        self.render_process = None           # RenderProcess after use_render_process()

    def show_board(self, board) -> None:
        """Put the calibration checkerboard (spacearm.controller.calibration.board.BoardConfig) in the cell."""
        self.base_T_board = board.pose.matrix() @ board.true_offset.matrix()
        self.board = board
        self._board_seen = None
        if self.render_process is not None:
            self.render_process.show_board(board)

    def use_render_process(self) -> "CameraService":
        """Render in a child process (firmware_sim/camera/render_process.py); call before start().
        The sink must be a named ShmFrameRing, the service made by from_files."""
        from spacearm.firmware_sim.camera.render_process import RenderProcess
        if self.seeds is None or not hasattr(self.sink, "name"):
            raise ValueError("a render process needs CameraService.from_files and a shared-memory ring")
        self.render_process = RenderProcess(self.sink.name, self.scene_config, 1.0 / self.period, *self.seeds,
                                            self.render_noise)
        if self.board is not None:
            self.render_process.show_board(self.board)
        return self

    @classmethod
    def from_files(cls, plant, sink, scene: str | Path | SceneConfig = DEFAULT_SCENE, frame_rate: float | None = None,
                   scene_seed: int = 0, noise_seed: int | None = 1) -> "CameraService":
        cam = CameraSimulator.from_configs(scene_seed=scene_seed, noise_seed=noise_seed)
        service = cls(plant, sink, cam, scene if isinstance(scene, SceneConfig) else load_scene(scene), frame_rate or 30.0)
        service.seeds = (scene_seed, noise_seed)
        return service

    # ------------------------------------------------------------------ plant side (SYNC thread)
    def on_sync(self, sync: int) -> None:
        """Called after each plant step: take an exposure when one is due (cheap: one FK of the
        true model). Free run: only when the render thread is free (frames are dropped, never
        queued); lockstep: every due one while the controller acquires, announced to it at once."""
        if self._stop:
            return
        t = self.plant.time
        trigger = self._trigger()
        if trigger is CameraTrigger.LOCKSTEP_IDLE and not self._requested(sync):
            self._next_exposure = t         # the first SYNC after acquisition starts exposes
            return
        lockstep = trigger is not CameraTrigger.FREE_RUN
        if t + 1e-9 < self._next_exposure or (not lockstep and self._pending):
            return
        self._next_exposure = t + self.period
        with self._wake:
            self._pending.append((t, sync, self.plant.tool_pose() @ self.camera.end_T_camera, self._stocked()))
            if lockstep:
                self.sink.announce_exposure(sync)
            self._wake.notify()

    def _requested(self, sync: int) -> bool:
        """Another reader asked for an exposure at or after a SYNC this camera has not exposed yet."""
        requested = getattr(self.sink, "requested_exposure", None)
        wanted = requested() if requested is not None else 0
        return 0 < wanted <= sync and self.sink.exposure_sync() < wanted

    def _trigger(self) -> CameraTrigger:
        trigger = getattr(self.sink, "trigger", None)
        return trigger() if trigger is not None else CameraTrigger.FREE_RUN

    # ------------------------------------------------------------------ render thread
    def start(self) -> "CameraService":
        self._thread = threading.Thread(target=self._run, name="sim-camera", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        with self._wake:
            self._stop = True
            self._wake.notify()
        if self._thread is not None:
            self._thread.join(2.0)
        if self.render_process is not None:
            self.render_process.close()

    def wait_rendered(self, timeout: float = 30.0) -> bool:
        """Wait until every exposure taken so far is rendered (False if `timeout` s passed). The
        exposures are fixed by plant time in lockstep; when their frames are done is the
        machine's business, so a count of frames is read after this, never while one renders."""
        end = time.monotonic() + timeout
        with self._wake:
            while self._pending and not self._stop:
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self._wake.wait(min(left, 0.05))
        return True

    def render_now(self, t: float, sync: int, base_T_camera: np.ndarray, stocked: frozenset[str] | None = None):
        """Render and publish one frame (also used directly by single-threaded tests). stocked:
        the stores that held an ORU at the exposure (None: ask the plant now)."""
        site = self._site_in_view(base_T_camera)
        camera_T_marker = inv_transform(base_T_camera) @ site.base_T_marker
        stocked = self._stocked() if stocked is None else stocked
        self.camera.scene.oru = self._oru if site.store in stocked else None
        image = self.camera.image(camera_T_marker, self._board_layers(base_T_camera), self.render_noise)
        self.frames += 1
        return self.sink.publish(image, t, camera_T_marker, sync)

    def _render(self, t: float, sync: int, base_T_camera: np.ndarray, stocked: frozenset[str]) -> None:
        if self.render_process is None:
            self.render_now(t, sync, base_T_camera, stocked)
        else:
            self.render_process.render(t, sync, base_T_camera, stocked)
            self.frames += 1

    def _stocked(self) -> frozenset[str]:
        """The stores that show an ORU now: the contact world's state when the plant has one
        (ORUs move during a changeout), else the cell file's."""
        orus = getattr(getattr(self.plant, "environment", None), "orus", None)
        if orus is None:
            return frozenset(site.store for site in self.sites if site.holds_oru)
        return frozenset(o.store for o in orus.values() if o.where == "store")

    def _board_layers(self, base_T_camera: np.ndarray) -> list[FlatLayer]:
        if self.board is None:
            return []
        camera_T_board = inv_transform(base_T_camera) @ self.base_T_board
        pose = camera_T_board.tobytes()
        if self._board_seen is None or self._board_seen[0] != pose:
            self._board_seen = (pose, self._draw_board(camera_T_board))
        return self._board_seen[1]           # the same layers at rest: the renderer gives its last image

    def _draw_board(self, camera_T_board: np.ndarray) -> list[FlatLayer]:
        cam = self.camera.camera
        nx, ny = self.board.inner
        centre = camera_T_board @ np.array([(nx - 1) * self.board.square / 2, (ny - 1) * self.board.square / 2, 0, 1])
        margin = self.camera.renderer.flat_margin(float(centre[2]))     # laid without growing its planes
        patch = board_patch(camera_T_board, self.board, cam.K, cam.dist, (cam.width, cam.height), margin)
        if patch is None:
            return []
        return [FlatLayer(patch[0], patch[1], float(centre[2]), patch[2], margin)]

    def _site_in_view(self, base_T_camera: np.ndarray) -> MarkerSite:
        """The marker nearest to the optical axis in front of the camera."""
        def off_axis(site: MarkerSite) -> float:
            p = (inv_transform(base_T_camera) @ site.base_T_marker)[:3, 3]
            return np.hypot(p[0], p[1]) / p[2] if p[2] > 0 else np.inf
        return min(self.sites, key=off_axis)

    def _run(self) -> None:
        if self.render_process is None:
            use_normal()   # rendering takes tens of ms: never at the nodes' real-time priority
        # else this thread only passes exposures to the render process and waits without the GIL:
        # it keeps the nodes' priority, so the little it holds the GIL it is never preempted by
        # ordinary processes while a node waits for it
        while True:
            with self._wake:
                while not self._pending and not self._stop:
                    self._wake.wait(0.5)
                if self._stop:
                    return
                exposure = self._pending[0]
            try:
                self._render(*exposure)
            except Exception:  # a bad frame must not kill the camera
                self.errors += 1
            finally:
                with self._wake:
                    self._pending.popleft()
            # Free run: leave the CPU to the nodes' heartbeat and SYNC threads between frames.
            # Lockstep: the controller waits for this camera, the nodes wait for the controller.
            if self._trigger() is CameraTrigger.FREE_RUN:
                time.sleep(self.min_gap)
