"""The simulated camera's renderer in a child process: frames off the nodes' and daemon's GIL.

A frame takes 35-60 ms of CPU, mostly in NumPy and OpenCV, but the Python around those calls
holds the GIL, and in the main job the nodes, the daemon's cycle and the renderer share one
interpreter (a real-time changeout had 898 overruns). With a render process the CameraService's
render thread only hands each exposure (plant time, SYNC, true camera pose, stores holding an
ORU) to a spawned process that renders it with its own CameraService (same scene, seeds and
noise stream, so the same frames) into the same shared-memory ring, and waits for the answer
without the GIL. Needs a named ShmFrameRing as the sink.
"""
from __future__ import annotations

import multiprocessing as mp
import os

RENDER_NICE = 10


class RenderProcess:
    def __init__(self, ring_name: str, scene, frame_rate: float, scene_seed: int, noise_seed: int | None,
                 render_noise: bool):
        ctx = mp.get_context("spawn")          # no copy of the parent's threads and locks
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_serve, name="sim-camera-render", daemon=True,
                                 args=(child, ring_name, scene, frame_rate, scene_seed, noise_seed, render_noise))
        self._proc.start()
        child.close()

    def render(self, t: float, sync: int, base_T_camera, stocked: frozenset[str]) -> int:
        """Render and publish one exposure; returns the frame's sequence number."""
        self._conn.send(("render", t, sync, base_T_camera, stocked))
        return self._answer()

    def show_board(self, board) -> None:
        self._conn.send(("board", board))
        self._answer()

    def _answer(self):
        answer = self._conn.recv()
        if isinstance(answer, str):
            raise RuntimeError(f"camera render process: {answer}")
        return answer

    def close(self) -> None:
        try:
            self._conn.send(None)
        except (OSError, ValueError):
            pass
        self._proc.join(2.0)
        if self._proc.is_alive():
            self._proc.terminate()
            self._proc.join(1.0)
        self._conn.close()


def _serve(conn, ring_name: str, scene, frame_rate: float, scene_seed: int, noise_seed: int | None,
           render_noise: bool) -> None:
    from spacearm.base.runtime.priority import use_normal
    from spacearm.base.vision.frames import ShmFrameRing
    from spacearm.firmware_sim.camera.service import CameraService

    use_normal()          # a simulator at SCHED_FIFO must not hand its priority to the renderer
    # Below the nodes and the daemon on a loaded machine too (free-run frames may be dropped):
    # spawned in their session it shares their CPU share (autogroup), and at the same nice its
    # start-up (~3 s of imports and scene set-up) starved the nodes' heartbeats for 0.75 s at
    # load 15 (bench_lockstep_camera.py with the render process).
    os.nice(RENDER_NICE)
    ring = ShmFrameRing.attach(ring_name, shared_tracker=True)
    service = CameraService.from_files(None, ring, scene, frame_rate, scene_seed, noise_seed)
    service.render_noise = render_noise
    try:
        while True:
            try:
                message = conn.recv()
            except EOFError:
                return
            if message is None:
                return
            try:
                if message[0] == "board":
                    service.show_board(message[1])
                    conn.send(0)
                else:
                    conn.send(service.render_now(*message[1:]))
            except Exception as exc:  # one bad frame: say so, keep serving
                conn.send(f"{type(exc).__name__}: {exc}")
    finally:
        ring.close()
