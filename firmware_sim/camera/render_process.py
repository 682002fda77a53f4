"""The simulated camera's renderer in a child process: frames off the nodes' and daemon's GIL.

A frame takes tens of ms of CPU, mostly in NumPy and OpenCV, but the Python around those calls
holds the GIL, and at normal priority the renderer is preempted while it holds it: the nodes'
SCHED_FIFO threads then wait for it as long as the machine's other processes keep it off a
core (100+ ms beside two CPU-bound processes, bench/bench_realtime.py gil). With a render
process the CameraService's render thread only hands each exposure (plant time, SYNC, true
camera pose, stores holding an ORU) to a spawned process that renders it with its own
CameraService (same scene, seeds and noise stream, so the same frames) into the same
shared-memory ring, and waits for the answer without the GIL. Needs a named ShmFrameRing.

Priority: the child starts from a thread of its own (Linux threads and the processes they
start inherit the starting thread's policy and nice), never at the nodes' priority.
- Beside nodes at SCHED_FIFO (`spacearm sim --rt-priority`, `demo`) it runs at SCHED_FIFO
  RENDER_PRIORITY (1): below every real-time thread of the stack (nodes, hub, cycle 50, vision
  40), above ordinary processes, as the camera's own processor would be. At normal priority
  it shares its session's CPU slice (autogroup) with whatever else runs there: beside two
  CPU-bound processes on a loaded machine (load 17-26) it drew 5 % of a core, its start-up took
  minutes and the main job's approach saw no frame for 30 s (bench/bench_realtime.py mainjob).
  Bounded: a frame costs tens of ms, free-run frames are paced (CameraService.min_gap) and
  lockstep frames render only while the cycle waits for them.
- Beside nodes at normal priority it starts at nice RENDER_NICE (its ~3 s start-up at their
  nice starved their heartbeats for 0.75 s at load 15, bench_lockstep_camera.py) and renders
  at nice 0 where it may (niced frames kept lockstep cycles waiting > 2 s at load 15).
"""
from __future__ import annotations

import multiprocessing as mp
import os
import threading

RENDER_PRIORITY = 1     # SCHED_FIFO beside nodes at SCHED_FIFO
RENDER_NICE = 10        # while the child starts up beside nodes at normal priority
RENDER_OPENCV_THREADS = 1


class RenderProcess:
    def __init__(self, ring_name: str, scene, frame_rate: float, scene_seed: int, noise_seed: int | None,
                 render_noise: bool):
        ctx = mp.get_context("spawn")          # no copy of the parent's threads and locks
        self._conn, child = ctx.Pipe()
        from spacearm.base.runtime.priority import current
        scheduling = current()
        priority = RENDER_PRIORITY if scheduling is not None and scheduling[0] == os.SCHED_FIFO else 0
        self._proc = ctx.Process(target=_serve, name="sim-camera-render", daemon=True,
                                 args=(child, ring_name, scene, frame_rate, scene_seed, noise_seed, render_noise,
                                       priority))
        starter = threading.Thread(target=self._start, args=(priority,), name="sim-camera-render-start",
                                   daemon=True)
        starter.start()
        starter.join()
        child.close()

    def _start(self, priority: int) -> None:
        from spacearm.base.runtime.priority import use_fifo, use_normal
        use_normal()
        if not priority or use_fifo(priority) is not None:
            me = threading.get_native_id()      # Linux: nice is per thread
            os.setpriority(os.PRIO_PROCESS, me, max(os.getpriority(os.PRIO_PROCESS, me), RENDER_NICE))
        self._proc.start()

    def scheduling(self) -> str:
        """The child's scheduling as the kernel has it now, e.g. "own process, SCHED_FIFO 1"."""
        pid = self._proc.pid
        try:
            if os.sched_getscheduler(pid) == os.SCHED_FIFO:
                return f"own process, SCHED_FIFO {os.sched_getparam(pid).sched_priority}"
            return f"own process, normal, nice {os.getpriority(os.PRIO_PROCESS, pid)}"
        except (OSError, TypeError):
            return "own process (ended)"

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
           render_noise: bool, priority: int) -> None:
    import cv2
    from spacearm.base.vision.frames import ShmFrameRing
    from spacearm.firmware_sim.camera.service import CameraService

    # one OpenCV thread: a frame then costs the least CPU (its worker threads cost more than they
    # save on this 2-core machine, bench_realtime.py render), and the cores are shared with the
    # nodes and the controller
    cv2.setNumThreads(RENDER_OPENCV_THREADS)
    ring = ShmFrameRing.attach(ring_name, shared_tracker=True)
    service = CameraService.from_files(None, ring, scene, frame_rate, scene_seed, noise_seed)
    service.render_noise = render_noise
    if not priority:
        try:
            os.setpriority(os.PRIO_PROCESS, 0, 0)
        except PermissionError:       # without CAP_SYS_NICE it stays niced: frames come later
            pass
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
