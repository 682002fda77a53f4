"""An in-process ORU cell stack for the HIL tests: simulated nodes with the contact world and
the daemon on python-can's virtual bus (the main job's configuration), lockstep clock."""
from __future__ import annotations

import threading
import time

from spacearm.controller.daemon.daemon import Daemon, DaemonOptions
from spacearm.firmware_sim.runner import start_simulator

PLANT = "configs/oru/plant_cell.toml"
# Slower heartbeats than configs/bus/arm.toml: see the file's header (shared, overloaded machine).
BUS_CONFIG = "configs/oru/bus_shared_machine.toml"


class OruStack:
    def __init__(self, record_dir=None, plant: str = PLANT, bus_config: str = BUS_CONFIG, bus: str | None = None):
        self.bus = bus or f"virtual:oru-test-{time.monotonic_ns()}"
        self.sim = start_simulator(self.bus, bus_config, plant, time_base="sync")
        self.daemon = Daemon(DaemonOptions(bus=self.bus, bus_config=bus_config, clock="lockstep", api=None,
                                           record_dir=record_dir))
        self.daemon.start()
        self.thread = threading.Thread(target=self.daemon.run, name="control-cycle", daemon=True)
        self.thread.start()
        self.lease = self.daemon.lease.take("hil-test")

    @property
    def world(self):
        return self.sim.plant.environment

    def call(self, cmd: str, **args):
        return self.daemon.handlers.handle(None, cmd, {**args, "lease": self.lease})

    def wait(self, predicate, timeout: float = 300.0, poll: float = 0.02, stop_ok: bool = True):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if not stop_ok and self.daemon.core.state == "stopped":
                raise AssertionError(f"protective stop: {self.daemon.core.stop_reason}")
            value = predicate()
            if value:
                return value
            time.sleep(poll)
        raise TimeoutError("condition not reached")

    def ready(self) -> None:
        """Enable and move to the arm's ready posture."""
        self.call("enable")
        self.wait(lambda: self.daemon.snapshot.state == "enabled", 10, stop_ok=False)
        motion = self.call("move_joints", q=list(self.daemon.arm.postures["ready"]))["motion"]
        self.wait(lambda: self.daemon.snapshot.motions_finished >= motion, 120, stop_ok=False)

    def oru_status(self) -> dict:
        return self.call("oru.status")

    def run_until(self, stage: int, subtask: int, timeout: float = 300.0) -> dict:
        """Wait until the runner is at (stage, subtask) (1-based) or has ended."""
        def reached():
            st = self.oru_status()
            ended = st["state"] not in ("running", "paused")
            return st if ended or (st["stage"], st["subtask"]) == (stage, subtask) else None
        return self.wait(reached, timeout, poll=0.05)

    def run_to_end(self, timeout: float = 600.0) -> dict:
        return self.wait(lambda: (st := self.oru_status())["state"] not in ("running", "paused") and st,
                         timeout, poll=0.1)

    def close(self) -> None:
        self.daemon.request_stop()
        self.thread.join(timeout=5)
        self.daemon.shutdown()
        self.sim.stop()
