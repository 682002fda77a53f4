"""The ORU changeout as the main job: enable, move to ready, run the task flow (ORU paper
Table 1, four stages), move home, disable; summary per stage from the runner's records.

The final pose errors are the plant's truth when the caller passes the simulator's contact
world (the demo does: on hardware a laser tracker would give them); without it they are
left out rather than guessed.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from spacearm.controller.daemon.daemon import Daemon


class ChangeoutFailed(Exception):
    pass


@dataclass
class StageSummary:
    number: int
    name: str
    arm_time: float = 0.0
    peak_force: float = 0.0           # N, compensated contact force
    peak_torque: float = 0.0          # N m
    peak_insert_force: float = 0.0    # N along the insertion axis


@dataclass
class ChangeoutResult:
    stages: list[StageSummary] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    seat_errors: dict[str, tuple[float, float]] = field(default_factory=dict)  # ORU -> (m, rad) plant truth
    recording: str | None = None
    cycles: int = 0
    stats: dict[str, Any] = field(default_factory=dict)
    wall_time: float = 0.0
    arm_time: float = 0.0


def _wait(daemon: Daemon, done: Callable[[], bool], what: str, timeout: float = 600.0) -> None:
    deadline = time.monotonic() + timeout
    while not done():
        if daemon.snapshot.state == "stopped":
            raise ChangeoutFailed(f"{what}: protective stop: {daemon.snapshot.stop_reason}")
        if time.monotonic() > deadline:
            raise ChangeoutFailed(f"{what}: not done within {timeout:.0f} s")
        time.sleep(0.01)


def run_changeout(daemon: Daemon, on_progress: Callable[[str, float], None], world=None) -> ChangeoutResult:
    """Run on a started daemon whose cycle runs on another thread."""
    result = ChangeoutResult()
    started = time.monotonic()
    lease = daemon.lease.take("changeout")
    call = lambda cmd, **a: daemon.handlers.handle(None, cmd, {**a, "lease": lease})   # noqa: E731
    on_progress("enable drives", 0.0)
    cycle = daemon.snapshot.tick.cycle
    call("enable")
    _wait(daemon, lambda: daemon.snapshot.tick.cycle > cycle + 1 and daemon.snapshot.state == "enabled", "enable")
    motion = call("move_joints", q=list(daemon.arm.postures["ready"]))["motion"]
    _wait(daemon, lambda: daemon.snapshot.motions_finished >= motion, "move to ready")
    t0 = daemon.snapshot.tick.time
    call("oru.run")
    while True:
        status = call("oru.status")
        if status["state"] not in ("running", "paused"):
            break
        if status.get("subtask") is not None:
            on_progress(f"stage {status['stage']} subtask {status['subtask']:2d}: {status['title']}",
                        status["progress"])
        time.sleep(0.05)
    if status["state"] != "done":
        raise ChangeoutFailed(f"ORU changeout {status['state']}: {status.get('failure')}")
    result.arm_time = daemon.snapshot.tick.time - t0
    names = [s.name for s in daemon.oru.changeout.stages]
    result.stages = [StageSummary(i + 1, n) for i, n in enumerate(names)]
    for r in status["records"]:
        s = result.stages[r["stage"]]
        s.arm_time += r["duration"]
        s.peak_force = max(s.peak_force, r["peak_force"])
        s.peak_torque = max(s.peak_torque, r["peak_torque"])
        s.peak_insert_force = max(s.peak_insert_force, r["peak_insert_force"])
    result.notes = list(dict.fromkeys(status["notes"]))
    on_progress("changeout done", 1.0)
    motion = call("move_joints", q=list(daemon.arm.postures["home"]))["motion"]
    _wait(daemon, lambda: daemon.snapshot.motions_finished >= motion, "move home")
    call("disable")
    _wait(daemon, lambda: not np.any(daemon.snapshot.measurement.joints_enabled), "disable")
    daemon.lease.release(lease)
    if world is not None:
        for name, o in world.orus.items():
            if o.where == "store":
                rel = np.linalg.inv(world.slots[o.store] @ world.slot_T_oru) @ o.pose
                result.seat_errors[f"{name} in {o.store}"] = (
                    float(np.linalg.norm(rel[:3, 3])), float(math.acos(np.clip(rel[2, 2], -1.0, 1.0))))
    result.recording = str(daemon.recorder.path) if daemon.recorder else None
    result.cycles = daemon.stats.cycles
    result.stats = daemon.stats.summary().as_dict()
    result.wall_time = time.monotonic() - started
    return result
