"""A lockstep daemon driven cycle by cycle from the test's own thread: commands go in between
two cycles and waits count cycles, never wall-clock time, so a run computes the same whatever
the machine's speed or load (issue 35). The simulator answers inline on the virtual bus."""
from __future__ import annotations

import uuid
from concurrent.futures import ThreadPoolExecutor, wait
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

from spacearm.base.config.bus import DEFAULT_BUS_CONFIG


def call_between_cycles(daemon, api: ThreadPoolExecutor, function: Callable, *args):
    """function(*args) on an API thread; the daemon cycles only while that thread waits for a
    cycle to take its request, so planning happens between two cycles however long it takes."""
    reply = api.submit(function, *args)
    while not reply.done():
        if daemon.core.requests_waiting:
            daemon.cycle_once()
        else:
            wait([reply], timeout=0.001)
    return reply.result()


class Script:
    """Runs `daemon` one cycle at a time; call(command, **args) under the test's lease.

    A command runs in an API thread as it does on the daemon; the script cycles only while
    that thread waits for the cycle to take a request (the core's pending queue), so every
    request is taken by the very next cycle and planning in the API thread happens between
    two cycles, however long it takes."""

    def __init__(self, daemon, lease: str) -> None:
        self.daemon, self.lease = daemon, lease
        self._api = ThreadPoolExecutor(1, thread_name_prefix="script-api")

    def call(self, command: str, **args):
        return call_between_cycles(self.daemon, self._api, self.daemon.handlers.handle,
                                   None, command, {"lease": self.lease, **args})

    @property
    def cycle(self) -> int:
        return self.daemon.snapshot.tick.cycle

    def run(self, cycles: int) -> None:
        for _ in range(cycles):
            self.daemon.cycle_once()

    def run_until(self, done: Callable[[dict], bool], max_cycles: int, what: str = "condition") -> int:
        """Cycles until done(status) holds; fails after max_cycles of controller time."""
        for n in range(max_cycles + 1):
            status = self.daemon.status()
            if done(status):
                return n
            self.daemon.cycle_once()
        raise AssertionError(f"{what} not reached within {max_cycles} cycles: {self.daemon.status()['stop_reason']}")

    def move_and_wait(self, command: str, max_cycles: int = 5000, **args) -> int:
        """Send a motion command, run until it finished; returns the cycle it finished on."""
        finished = self.daemon.status()["motions_finished"]
        self.call(command, **args)
        self.run_until(lambda s: s["motions_finished"] > finished, max_cycles, f"end of {command}")
        return self.cycle


@contextmanager
def lockstep_stack(plant: str | Path, *, arm: Path | None = None, bus_config: Path = DEFAULT_BUS_CONFIG,
                   record_dir: Path | None = None, tag: str = "script", bus: str | None = None) -> Iterator[object]:
    """A simulator on SYNC time on a fresh virtual bus (or `bus`, e.g. a redundant pair) and a
    started lockstep daemon (not cycling)."""
    from spacearm.controller.daemon.daemon import Daemon, DaemonOptions
    from spacearm.firmware_sim.runner import start_simulator
    bus = bus or f"virtual:{tag}-{uuid.uuid4().hex[:8]}"
    sim = start_simulator(bus, bus_config, plant=plant, time_base="sync")
    options = DaemonOptions(bus=bus, bus_config=bus_config, clock="lockstep", api=None, record_dir=record_dir)
    if arm is not None:
        options.arm = arm
    daemon = Daemon(options)
    daemon.plant_simulator = sim        # for tests that judge the plant's truth
    try:
        daemon.start()
        yield daemon
    finally:
        daemon.request_stop()
        daemon.shutdown()
        sim.stop()


@contextmanager
def scripted_daemon(plant: str | Path, *, arm: Path | None = None, bus_config: Path = DEFAULT_BUS_CONFIG,
                    record_dir: Path | None = None, enable: bool = True,
                    cycle_hook: Callable[[], None] | None = None, bus: str | None = None) -> Iterator[Script]:
    """lockstep_stack cycled by the caller. cycle_hook runs after every cycle (a test slows the
    process with it)."""
    with lockstep_stack(plant, arm=arm, bus_config=bus_config, record_dir=record_dir, bus=bus) as daemon:
        if cycle_hook is not None:
            cycle_once = daemon.cycle_once

            def slowed_cycle():
                snapshot = cycle_once()
                cycle_hook()
                return snapshot
            daemon.cycle_once = slowed_cycle
        script = Script(daemon, daemon.lease.take("test"))
        if enable:
            script.call("enable")
            script.run_until(lambda s: s["state"] == "enabled", 500, "enabled")
        yield script
