"""The vision worker in controller time, for lockstep runs: same results, fixed timing.

In real time the VisionWorker thread measures frames as they come and the cycle takes whatever
result is newest, so which cycle sees which frame depends on the machine. In lockstep that made
results depend on load (and the clock had to be held to a few times real time so frames were
not stale). Here the camera is triggered in plant time (base/vision/frames.py CameraTrigger)
and announces each exposure's SYNC before the nodes answer it: `on_cycle(s)` waits (in wall
time, the cycle has no deadline in lockstep) until that frame is published, measures it on the
cycle's own thread and releases the result `latency_cycles` later, the delay a real camera and
worker would add (one 30 fps read-out, ~33 ms, plus ~7 ms of measurement: two 20 ms cycles).
So a seed fixes every frame and every cycle that uses it, and the run goes as fast as the
renderer and the pipeline allow. A camera that stops publishing is waited for once
(FRAME_WAIT); then the cycle goes on without frames and the approach's own camera_stopped
rule applies.

The camera acquires only while a mode reads `latest()` (the approach): the first call in a
cycle asks for frames from the next SYNC on, a cycle without a call stops acquisition, so the
simulated camera renders nothing during the rest of a changeout.
"""
from __future__ import annotations

import time
from collections import deque

from spacearm.base.vision.frames import CameraTrigger, FrameSource
from spacearm.controller.vision.pipeline import VisionPipeline, VisionResult
from spacearm.controller.vision.worker import VisionWorker

LATENCY_CYCLES = 2
FRAME_WAIT = 10.0            # s of wall time for an announced frame (renders take 0.05-0.3 s)


class LockstepVision:
    def __init__(self, source: FrameSource, pipeline: VisionPipeline | None = None,
                 latency_cycles: int = LATENCY_CYCLES):
        self.source = source
        self._worker = VisionWorker(source, pipeline)       # its step(), never its thread
        self.latency_cycles = latency_cycles
        self._queue: deque[tuple[int, tuple[VisionResult, int]]] = deque()   # (release sync, result)
        self._latest: tuple[VisionResult, int] | None = None
        self._wanted = False            # latest() was called since the last on_cycle
        self._acquiring = False
        self._given_up = 0              # announced exposure not waited for again (camera stopped)
        self.wait_time = 0.0            # s of wall time the cycle waited for frames

    @property
    def pipeline(self) -> VisionPipeline:
        return self._worker.pipeline

    @property
    def processed(self) -> int:
        return self._worker.processed

    @property
    def processing_times(self) -> list[float]:
        return self._worker.processing_times

    def latest(self) -> tuple[VisionResult, int] | None:
        """(newest released result, SYNC number of its exposure), or None before the first."""
        self._wanted = True
        return self._latest

    def on_cycle(self, sync: int) -> None:
        """Called by the cycle with this SYNC's number, before the modes run."""
        self._wait_for_announced()
        if self._worker.step():
            result, exposed = self._worker.latest()
            self._queue.append((exposed + self.latency_cycles, (result, exposed)))
        while self._queue and self._queue[0][0] <= sync:
            self._latest = self._queue.popleft()[1]
        self._acquire(self._wanted)
        self._wanted = False

    def _wait_for_announced(self) -> None:
        announced = self.source.exposure_sync()
        if announced <= self._given_up or self.source.published_sync() >= announced:
            return
        started = time.monotonic()
        while self.source.published_sync() < announced:
            if time.monotonic() - started > FRAME_WAIT:
                self._given_up = announced
                break
            time.sleep(0.0005)
        self.wait_time += time.monotonic() - started

    def _acquire(self, on: bool) -> None:
        if on != self._acquiring:
            self._acquiring = on
            self.source.set_trigger(CameraTrigger.LOCKSTEP if on else CameraTrigger.LOCKSTEP_IDLE)

    def start(self) -> "LockstepVision":
        self.source.set_trigger(CameraTrigger.LOCKSTEP_IDLE)
        return self

    def stop(self) -> None:
        """Hand the camera back to free run (a later real-time daemon on the same ring)."""
        self.source.set_trigger(CameraTrigger.FREE_RUN)
