"""The vision worker's scheduling (controller/vision/worker.py): with the cycle at SCHED_FIFO it
runs BELOW_CYCLE under it (never at or above), with a normal cycle at normal priority."""
from __future__ import annotations

import os
import time

import pytest

from spacearm.base.vision.frames import LocalFrameSource
from spacearm.controller.vision.worker import BELOW_CYCLE, VisionWorker


def policy_of(worker: VisionWorker) -> tuple[int, int]:
    tid = worker._thread.native_id
    return os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority


def started(worker: VisionWorker) -> VisionWorker:
    worker.start()
    deadline = time.monotonic() + 5.0
    while worker.scheduling == "normal" and worker.priority and time.monotonic() < deadline:
        time.sleep(0.01)
    return worker


def test_worker_runs_below_a_real_time_cycle():
    worker = started(VisionWorker(LocalFrameSource(), cycle_priority=50))
    try:
        if "not permitted" in worker.scheduling:
            pytest.skip(worker.scheduling)
        assert worker.scheduling == f"SCHED_FIFO {50 - BELOW_CYCLE}"
        assert policy_of(worker) == (os.SCHED_FIFO, 50 - BELOW_CYCLE)
    finally:
        worker.stop()


def test_worker_of_a_normal_cycle_stays_normal():
    worker = started(VisionWorker(LocalFrameSource()))
    try:
        time.sleep(0.05)
        assert worker.priority == 0 and policy_of(worker)[0] == os.SCHED_OTHER
    finally:
        worker.stop()


@pytest.mark.parametrize("cycle, worker", [(0, 0), (1, 0), (5, 1), (50, 50 - BELOW_CYCLE), (99, 99 - BELOW_CYCLE)])
def test_worker_priority_is_always_below_the_cycle(cycle, worker):
    assert VisionWorker(LocalFrameSource(), cycle_priority=cycle).priority == worker
