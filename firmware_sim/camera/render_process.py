"""The simulated camera's renderer in a child process: frames off the nodes' and daemon's GIL.

A frame takes tens of ms of CPU, mostly in NumPy and OpenCV, but the Python around those calls
holds the GIL, and at normal priority the renderer is preempted while it holds it: the nodes'
SCHED_FIFO threads then wait for it as long as the machine's other processes keep it off a
core (100+ ms beside two CPU-bound processes, bench/bench_realtime.py gil). With a render
process the CameraService's render thread only hands each exposure (plant time, SYNC, true
camera pose, stores holding an ORU) to a spawned process that renders it with its own
CameraService (same scene, seeds and noise stream, so the same frames) into the same
shared-memory ring, and waits for the answer without the GIL. Needs a named ShmFrameRing.

Priority: the child starts from a thread at normal priority and nice RENDER_NICE (Linux
threads and the processes they start inherit the starting thread's policy and nice), so its
start-up (~3 s of imports and scene set-up) runs neither at the nodes' SCHED_FIFO priority nor
beside them at their nice: at nice 0 it starved normal-priority nodes' heartbeats for 0.75 s
at load 15 (bench_lockstep_camera.py). Once set up it renders at nice 0 where it may (frames
from a niced renderer kept lockstep cycles waiting > 2 s at load 15): a frame costs about
10 ms of CPU, bounded by the frame rate.
"""
from __future__ import annotations

import multiprocessing as mp
import os
import threading

RENDER_NICE = 10        # while the child starts up
SERVE_NICE = 0          # once it renders


class RenderProcess:
    def __init__(self, ring_name: str, scene, frame_rate: float, scene_seed: int, noise_seed: int | None,
                 render_noise: bool):
        ctx = mp.get_context("spawn")          # no copy of the parent's threads and locks
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(target=_serve, name="sim-camera-render", daemon=True,
                                 args=(child, ring_name, scene, frame_rate, scene_seed, noise_seed, render_noise))
        starter = threading.Thread(target=self._start_niced, name="sim-camera-render-start", daemon=True)
        starter.start()
        starter.join()
        child.close()

    def _start_niced(self) -> None:
        from spacearm.base.runtime.priority import use_normal
        use_normal()
        me = threading.get_native_id()          # Linux: nice is per thread
        os.setpriority(os.PRIO_PROCESS, me, max(os.getpriority(os.PRIO_PROCESS, me), RENDER_NICE))
        self._proc.start()

    def scheduling(self) -> str:
        """The child's scheduling as the kernel has it now, e.g. "own process, normal, nice 0"."""
        pid = self._proc.pid
        try:
            policy = "SCHED_FIFO" if os.sched_getscheduler(pid) == os.SCHED_FIFO else "normal"
            return f"own process, {policy}, nice {os.getpriority(os.PRIO_PROCESS, pid)}"
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
           render_noise: bool) -> None:
    from spacearm.base.runtime.priority import use_normal
    from spacearm.base.vision.frames import ShmFrameRing
    from spacearm.firmware_sim.camera.service import CameraService

    use_normal()          # already so (see the module's doc); never the nodes' SCHED_FIFO
    ring = ShmFrameRing.attach(ring_name, shared_tracker=True)
    service = CameraService.from_files(None, ring, scene, frame_rate, scene_seed, noise_seed)
    service.render_noise = render_noise
    try:
        os.setpriority(os.PRIO_PROCESS, 0, SERVE_NICE)
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
