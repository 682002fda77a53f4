"""`spacearm daemon`: start the central controller (CANopen master + 20 ms cycle + API)."""
from __future__ import annotations

import signal
import sys
from pathlib import Path

import typer

from spacearm.console.errors import CommandFailed, friendly_errors
from spacearm.controller.daemon.command_api import ApiError
from spacearm.controller.daemon.cycle_stats import CycleThresholds
from spacearm.controller.daemon.daemon import Daemon, DaemonOptions
from spacearm.base.config.bus import DEFAULT_BUS_CONFIG
from spacearm.drivers.errors import DriverError


def register(app: typer.Typer) -> None:
    @app.command()
    @friendly_errors
    def daemon(bus: str = typer.Option("virtual:spacearm", help="CAN bus: virtual:NAME, loopback:..., socketcan:vcan0."),
               arm: Path = typer.Option(Path("configs/arm/oru_testbed_6dof.toml"), help="Arm file."),
               bus_config: Path = typer.Option(DEFAULT_BUS_CONFIG, help="Bus file (node IDs, heartbeats)."),
               clock: str = typer.Option("realtime", help="realtime: SYNC on absolute deadlines; "
                                         "lockstep: next SYNC as soon as every node answered."),
               period: float = typer.Option(0.02, help="Cycle period, s."),
               api: str = typer.Option("tcp:127.0.0.1:7440", help="Command API address (tcp:HOST:PORT, unix:PATH)."),
               expose: bool = typer.Option(False, "--expose", help="Allow a non-loopback API address (needs --token)."),
               token: str = typer.Option(None, envvar="SPACEARM_TOKEN", help="API token (required with --expose)."),
               record_dir: Path = typer.Option(Path("runs"), help="Where recordings go."),
               record: bool = typer.Option(True, "--record/--no-record", help="Record every cycle from start."),
               max_cycles: int = typer.Option(0, help="Stop after this many cycles (0: run until signalled)."),
               rt_priority: int = typer.Option(50, min=0, max=99, help="SCHED_FIFO priority of the cycle with "
                                               "--clock realtime (0: normal scheduling); needs root or an "
                                               "rtprio limit, else the daemon runs on and says so."),
               camera: str = typer.Option(None, "--camera", help="Shared-memory frame ring of the eye-in-hand "
                                          "camera (spacearm sim --camera NAME); enables `approach`.")) -> None:
        """Run the controller daemon until SIGINT/SIGTERM; the arm starts disabled, brakes on."""
        if clock not in ("realtime", "lockstep"):
            raise CommandFailed(f"--clock must be realtime or lockstep, got {clock!r}")
        if not 0.001 <= period <= 1.0:
            raise CommandFailed(f"--period must be within [0.001, 1] s, got {period}")
        options = DaemonOptions(bus=bus, arm=arm, bus_config=bus_config, clock=clock, period=period,
                                api=api, expose=expose, token=token,
                                record_dir=record_dir if record else None,
                                thresholds=CycleThresholds(), camera=camera, rt_priority=rt_priority)
        try:
            controller = Daemon(options)
        except ApiError as exc:
            raise CommandFailed(str(exc)) from None
        signal.signal(signal.SIGTERM, lambda *_: controller.request_stop())
        signal.signal(signal.SIGINT, lambda *_: controller.request_stop())
        try:
            controller.start()
        except DriverError as exc:
            controller.shutdown()
            raise CommandFailed(str(exc)) from None
        where = f"API on {api}" if api else "no API"
        print(f"spacearm daemon: {controller.model.name} on {bus}, {clock} clock, "
              f"{1e3 * period:.1f} ms cycle ({controller.scheduling}), {where}"
              + (f", recording {controller.recorder.path}" if controller.recorder else ""), flush=True)
        try:
            controller.run(max_cycles or None)
        finally:
            controller.shutdown()
            summary = controller.stats.summary()
            print(f"spacearm daemon: stopped after {summary.cycles} cycles, overruns {summary.overruns}",
                  file=sys.stderr)
