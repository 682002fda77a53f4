"""Runs the vision pipeline on its own thread at frame rate, never inside the control cycle.

The worker polls a FrameSource (ShmFrameRing from the simulator's process, or a local source),
measures each new frame with the previous good pose as the prior (tracking window), and keeps
the newest result. The control cycle only reads `latest()`: one attribute read, no lock.
"""
from __future__ import annotations

import threading
import time

import numpy as np

from spacearm.base.vision.frames import CameraTrigger, FrameSource
from spacearm.controller.vision.pipeline import VisionPipeline, VisionResult
from spacearm.base.runtime.priority import use_fifo, use_normal

PRIOR_MAX_AGE = 0.5          # s (frame time): an older good pose is not used as prior
# With the cycle at SCHED_FIFO the worker runs this far below it: above every ordinary process,
# so on a loaded machine a frame's wall time is its CPU time. bench/bench_vision.py --fifo 40
# at load 16 on 2 cores: full frame 32.6 ms wall at normal priority (7.5 ms CPU + 24.4 ms
# waiting for a core) vs 6.7 ms at FIFO 40. Bounded: ~7.5 ms per frame, at most the camera's
# 30 frames a second (a quarter of a core), and never ahead of the cycle.
BELOW_CYCLE = 10


class VisionWorker:
    def __init__(self, source: FrameSource, pipeline: VisionPipeline | None = None, poll: float = 0.002,
                 cycle_priority: int = 0):
        """cycle_priority: the control cycle's SCHED_FIFO priority (0: normal scheduling); the
        worker then runs at BELOW_CYCLE under it, else at normal priority."""
        self.source = source
        below = max(cycle_priority - BELOW_CYCLE, 1)
        self.priority = below if below < cycle_priority else 0      # 0: normal scheduling
        self.scheduling = "normal"
        self.pipeline = pipeline or VisionPipeline.from_configs()
        self.poll = poll
        self._latest: tuple[VisionResult, int] | None = None   # (result, frame sync)
        self._prior: tuple[float, np.ndarray] | None = None
        self._last_seq = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.processed = 0
        self.processing_times: list[float] = []

    def latest(self) -> tuple[VisionResult, int] | None:
        """(newest result, SYNC number of its exposure), or None before the first frame."""
        return self._latest

    def on_cycle(self, sync: int) -> None:
        """Nothing to do in the cycle: this worker runs on its own thread (free-running camera)."""

    def step(self) -> bool:
        """Process the newest frame if there is one; True if a frame was processed."""
        frame = self.source.latest()
        if frame is None or frame.seq == self._last_seq:
            return False
        self._last_seq = frame.seq
        prior = None
        if self._prior is not None and frame.timestamp - self._prior[0] <= PRIOR_MAX_AGE:
            prior = self._prior[1]
        result = self.pipeline.process(frame, prior)
        if result.ok:
            self._prior = (frame.timestamp, result.camera_T_marker)
        self._latest = (result, frame.sync)
        self.processed += 1
        self.processing_times = (self.processing_times + [result.processing_time])[-200:]
        return True

    def start(self) -> "VisionWorker":
        set_trigger = getattr(self.source, "set_trigger", None)
        if set_trigger is not None:
            set_trigger(CameraTrigger.FREE_RUN)      # real time: the camera runs at its own rate
        self._thread = threading.Thread(target=self._run, name="vision", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)

    def _run(self) -> None:
        # Several ms of CPU per frame: never at or above the cycle's real-time priority.
        use_normal()
        if self.priority:
            problem = use_fifo(self.priority)
            self.scheduling = problem or f"SCHED_FIFO {self.priority}"
        while not self._stop.is_set():
            try:
                busy = self.step()
            except Exception:       # a bad frame must not end the worker
                busy = False
            if not busy:
                time.sleep(self.poll)
