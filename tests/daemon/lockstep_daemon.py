"""An in-process daemon on a lockstep clock and a simulator on a fresh virtual bus, enabled,
for tests that drive the daemon through its own command handlers."""
from __future__ import annotations

import threading
import time
import uuid
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

from spacearm.base.config.bus import DEFAULT_BUS_CONFIG


@contextmanager
def enabled_daemon(plant: str | Path, *, arm: Path | None = None, bus_config: Path = DEFAULT_BUS_CONFIG,
                   record_dir: Path | None = None, timeout: float = 120.0) -> Iterator[tuple[object, Callable]]:
    """Yields (daemon, call): call(command, **args) runs a command under the test's lease. The
    timeout only ends a hung test: lockstep runs as fast as the nodes answer."""
    from spacearm.controller.daemon.daemon import Daemon, DaemonOptions
    from spacearm.firmware_sim.runner import start_simulator
    bus = f"virtual:test-{uuid.uuid4().hex[:8]}"
    sim = start_simulator(bus, bus_config, plant=plant, time_base="sync")
    options = DaemonOptions(bus=bus, bus_config=bus_config, clock="lockstep", api=None, record_dir=record_dir)
    if arm is not None:
        options.arm = arm
    daemon = Daemon(options)
    try:
        daemon.start()
        threading.Thread(target=daemon.run, daemon=True).start()
        key = daemon.lease.take("test")
        call = lambda cmd, **args: daemon.handlers.handle(None, cmd, {"lease": key, **args})   # noqa: E731
        call("enable")
        deadline = time.monotonic() + timeout
        while daemon.status()["state"] != "enabled":
            assert time.monotonic() < deadline, daemon.status()["stop_reason"]
            time.sleep(0.02)
        yield daemon, call
    finally:
        daemon.request_stop()
        time.sleep(0.1)
        daemon.shutdown()
        sim.stop()
