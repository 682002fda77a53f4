"""`spacearm daemon`: start the central controller (CANopen master + 20 ms cycle + API)."""
from __future__ import annotations

import os
import signal
import sys
import threading
from pathlib import Path

import can
import typer

from spacearm.console.errors import BadInput, CommandFailed, classify, friendly_errors, report
from spacearm.controller.daemon.command_api import ApiError
from spacearm.controller.daemon.cycle_stats import CycleThresholds
from spacearm.controller.daemon.daemon import Daemon, DaemonOptions
from spacearm.controller.recording.can_trace import TraceLimit
from spacearm.base.config.bus import DEFAULT_BUS_CONFIG
from spacearm.base.transport import BusSpecError
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
               api: str = typer.Option("tcp:127.0.0.1:7440", envvar="SPACEARM_API",
                                       help="Command API address (tcp:HOST:PORT, unix:PATH); the consoles "
                                       "read the same variable."),
               expose: bool = typer.Option(False, "--expose", help="Allow a non-loopback API address (needs --token)."),
               token: str = typer.Option(None, envvar="SPACEARM_TOKEN", help="API token (required with --expose)."),
               record_dir: Path = typer.Option(Path("runs"), help="Where recordings go."),
               record: bool = typer.Option(True, "--record/--no-record", help="Record every cycle from start."),
               can_trace_max_mb: float = typer.Option(64.0, min=0.0, help="Raw CAN trace: MB per file before it "
                                                      "rotates (0: no limit); ~320 MB/h at 50 Hz."),
               can_trace_files: int = typer.Option(4, min=0, help="Raw CAN trace: rotated files kept (.1 newest)."),
               max_cycles: int = typer.Option(0, help="Stop after this many cycles (0: run until signalled)."),
               rt_priority: int = typer.Option(50, min=0, max=99, help="SCHED_FIFO priority of the cycle with "
                                               "--clock realtime (0: normal scheduling); needs root or an "
                                               "rtprio limit, else the daemon runs on and says so."),
               camera: str = typer.Option(None, "--camera", help="Shared-memory frame ring of the eye-in-hand "
                                          "camera (spacearm sim --camera NAME); enables `approach`.")) -> None:
        """Run the controller daemon until SIGINT/SIGTERM; the arm starts disabled, brakes on."""
        if clock not in ("realtime", "lockstep"):
            raise BadInput(f"--clock must be realtime or lockstep, got {clock!r}")
        if not 0.001 <= period <= 1.0:
            raise BadInput(f"--period must be within [0.001, 1] s, got {period}")
        options = DaemonOptions(bus=bus, arm=arm, bus_config=bus_config, clock=clock, period=period,
                                api=api, expose=expose, token=token,
                                record_dir=record_dir if record else None,
                                thresholds=CycleThresholds(), camera=camera, rt_priority=rt_priority,
                                can_trace_limit=TraceLimit(int(can_trace_max_mb * 1e6), can_trace_files))
        code = 0
        try:
            _serve(options, max_cycles)
        except CommandFailed as exc:     # bad input exits 2 like every command's (classify)
            code = report(*classify(exc), as_json=False).code
        _quick_exit(int(code or 0))


def _quick_exit(code: int) -> None:
    """Leave without the interpreter's teardown once shutdown has closed everything: it costs
    a few hundred ms of a signalled daemon's one-second budget and prints ~25 lines of nanobind
    leak warnings from ruckig's planners. In-process callers (a test's CliRunner, whose
    stdout is not the process's) get a normal SystemExit."""
    if sys.stdout is not sys.__stdout__:
        raise SystemExit(code)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


class _Interrupted(Exception):
    """SIGINT/SIGTERM before the cycle runs (during bring-up): abandon the boot at once."""


def _serve(options: DaemonOptions, max_cycles: int) -> None:
    """Build, boot and run the daemon; every way out goes through shutdown (drives disabled,
    recording closed), and SIGINT/SIGTERM end it at any stage, bring-up included."""
    running = threading.Event()
    controller: Daemon | None = None

    def on_signal(signum, _frame) -> None:
        if running.is_set() and controller is not None:
            controller.request_stop()        # the cycle loop ends within one period
        else:
            raise _Interrupted(signal.Signals(signum).name)

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    try:
        try:
            controller = Daemon(options)
        except ApiError as exc:
            raise CommandFailed(str(exc), exc.code.value) from None
        except OSError as exc:   # the API address is in use or cannot be bound
            raise CommandFailed(f"cannot open the command API on {options.api}: {exc.strerror or exc} "
                                "(another daemon running? use --api)", "api_address") from None
        except (BusSpecError, can.CanError) as exc:
            raise BadInput(str(exc), "bad_bus") from None
        print(f"spacearm daemon booting {controller.hardware.node_count} nodes on {options.bus} "
              f"(boot timeout {controller.hardware.boot_timeout:.1f} s)", file=sys.stderr, flush=True)
        try:
            controller.start()
        except (BusSpecError, can.CanError) as exc:   # the transport checks its spec on connect
            raise BadInput(str(exc), "bad_bus") from None
        except DriverError as exc:
            raise CommandFailed(f"bus {options.bus}: {exc}", "boot_failed") from None
        running.set()
        where = f"API on {options.api}" if options.api else "no API"
        print(f"spacearm daemon: {controller.model.name} on {options.bus}, {options.clock} clock, "
              f"{1e3 * options.period:.1f} ms cycle ({controller.scheduling}), {where}"
              + (f", recording {controller.recorder.path}" if controller.recorder else ""), flush=True)
        controller.run(max_cycles or None)
    except _Interrupted as exc:
        print(f"spacearm daemon: {exc} during bring-up, shutting down", file=sys.stderr)
    finally:
        running.set()   # a second signal during shutdown only asks for the stop again
        if controller is not None:
            controller.shutdown()
            summary = controller.stats.summary()
            print(f"spacearm daemon: stopped after {summary.cycles} cycles, overruns {summary.overruns}",
                  file=sys.stderr)
