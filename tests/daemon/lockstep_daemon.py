"""An in-process daemon on a lockstep clock and a simulator on a fresh virtual bus, enabled,
for tests that drive the daemon through its own command handlers."""
from __future__ import annotations

import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

from spacearm.base.config.bus import DEFAULT_BUS_CONFIG
from tests.daemon.lockstep_script import lockstep_stack


@contextmanager
def enabled_daemon(plant: str | Path, *, arm: Path | None = None, bus_config: Path = DEFAULT_BUS_CONFIG,
                   record_dir: Path | None = None, timeout: float = 120.0) -> Iterator[tuple[object, Callable]]:
    """Yields (daemon, call): call(command, **args) runs a command under the test's lease. The
    timeout only ends a hung test: lockstep runs as fast as the nodes answer."""
    with lockstep_stack(plant, arm=arm, bus_config=bus_config, record_dir=record_dir, tag="test") as daemon:
        cycling = threading.Thread(target=daemon.run, daemon=True)
        cycling.start()
        key = daemon.lease.take("test")
        call = lambda cmd, **args: daemon.handlers.handle(None, cmd, {"lease": key, **args})   # noqa: E731
        call("enable")
        deadline = time.monotonic() + timeout
        while daemon.status()["state"] != "enabled":
            assert time.monotonic() < deadline, daemon.status()["stop_reason"]
            time.sleep(0.02)
        try:
            yield daemon, call
        finally:
            daemon.request_stop()
            cycling.join(5)
