"""A lockstep daemon and simulator driven cycle by cycle from the test's own thread, for stop
tests that need a stop at an exact cycle: enable, start a motion, trigger a stop, run on,
then judge the recording (controller/daemon/stop_metrics.py)."""
from __future__ import annotations

import uuid
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from spacearm.controller.recording.mcap_reader import read_recording

ARM = Path("configs/arm/oru_testbed_6dof.toml")
PLANT = Path("configs/plant/oru_testbed_nominal.toml")


class SteppedDaemon:
    def __init__(self, daemon, sim):
        self.daemon, self.sim = daemon, sim
        self.core = daemon.core

    @property
    def m(self):
        return self.core.last_measurement

    def cycles(self, n: int = 1):
        for _ in range(n):
            snapshot = self.daemon.cycle_once()
        return snapshot

    def until(self, predicate: Callable[[object], bool], limit: int = 500) -> None:
        for _ in range(limit):
            if predicate(self.cycles()):
                return
        raise AssertionError(f"condition not reached in {limit} cycles: {self.daemon.status()['stop_reason']}")

    def apply(self, command: Callable):
        """A core command as the cycle applies it (with this cycle's measurement)."""
        return command(self.m.time, self.m)

    def enable(self) -> None:
        self.apply(self.core.cmd_enable)
        self.until(lambda s: s.state == "enabled")

    def start(self, name: str, plan) -> None:
        from spacearm.controller.modes import PlannedMode
        start = self.apply(self.core.motion_start)
        self.apply(lambda t, m: self.core.start_planned(t, m, PlannedMode(name, plan, 0.0, name), start))

    def jog_at_full_speed(self, joint: int, delta: float = 0.6) -> None:
        """Jog one joint and run until it has moved at its speed limit for 10 cycles."""
        self.start("jog", self.daemon.planner.jog(self.apply(self.core.motion_start), joint, delta))
        v_max = self.daemon.model.v_max[joint]
        fast = [0]

        def cruising(s) -> bool:
            fast[0] = fast[0] + 1 if abs(s.measurement.dq[joint]) > 0.99 * v_max else 0
            return fast[0] >= 10
        self.until(cruising)

    def stop_and_settle(self, command: Callable | None = None, cycles: float = 1.5) -> None:
        """A stop (the operator's unless given), then `cycles` s of cycles."""
        self.apply(command or self.core.cmd_stop)
        self.cycles(int(round(cycles / self.daemon.options.period)))

    def brakes(self) -> list[bool]:
        """The simulated joints' brakes, as the plant has them."""
        return [j.brake_engaged for j in self.sim.plant.joints]

    def recording(self):
        """(t, q, stop events) of the recording so far (the file is closed and read back)."""
        info = self.daemon.stop_recording()
        rec = read_recording(info["path"])
        cycles = rec.topic("/cycle")
        t = np.array([c.data["t"] for c in cycles])
        q = np.array([c.data["q"] for c in cycles])
        events = [e.data for e in rec.topic("/events")]
        return t, q, events, cycles


def with_sync_period(period: float, folder: Path) -> Path:
    """The arm's bus with slow heartbeats (hil_tests/harness.py: lockstep runs cycles in no wall
    time, but heartbeats are timed in wall time, and a loaded machine starves their threads)
    and its SYNC period set to the daemon's (the simulator steps its physics by it)."""
    from hil_tests.harness import patient_bus
    path = patient_bus(folder / f"bus_{1e3 * period:g}ms.toml")
    text = path.read_text()
    assert "sync_period = 0.02 " in text
    path.write_text(text.replace("sync_period = 0.02 ", f"sync_period = {period} ", 1))
    return path


@contextmanager
def stepped_daemon(tmp_path: Path, *, arm: Path = ARM, plant: Path = PLANT,
                   period: float = 0.02) -> Iterator[SteppedDaemon]:
    from spacearm.controller.daemon.daemon import Daemon, DaemonOptions
    from spacearm.firmware_sim.runner import start_simulator
    bus_config = with_sync_period(period, tmp_path)
    bus = f"virtual:stops-{uuid.uuid4().hex[:8]}"
    sim = start_simulator(bus, bus_config, plant=plant, time_base="sync")
    daemon = Daemon(DaemonOptions(bus=bus, arm=arm, bus_config=bus_config, clock="lockstep", api=None,
                                  record_dir=tmp_path, period=period))
    try:
        daemon.start()
        yield SteppedDaemon(daemon, sim)
    finally:
        daemon.shutdown()
        sim.stop()
