"""`spacearm hub`: run the loopback CAN hub for `--bus loopback:...` in the foreground.

    spacearm hub [--host 127.0.0.1] [--port 29536] [--idle-exit SECONDS] [--rt-priority N] [--fault-file PATH]

Optional: the first `loopback:` client on this machine starts a hub by itself when none
answers (it exits after 30 s without clients). Run it explicitly to keep one up, to see its
log, or with SPACEARM_HUB_AUTOSTART=0 on the clients. Prints one line
"spacearm hub listening on HOST:PORT (pid N)" when ready.
"""
from __future__ import annotations

from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    from spacearm.base.transport.hub import DEFAULT_HOST, DEFAULT_PORT
    from spacearm.base.transport.loopback import default_hub_address

    try:   # the same address the buses use ($SPACEARM_HUB), so `spacearm hub &` serves them
        default_host, default_port = default_hub_address()
    except ValueError:
        default_host, default_port = DEFAULT_HOST, DEFAULT_PORT

    @app.command("hub")
    def hub(
        host: str = typer.Option(default_host, "--host", help="address to bind: 127.0.0.1 or ::1 (others are refused)"),
        port: int = typer.Option(default_port, "--port", min=0, max=65535, help="TCP port (0 = any free port)"),
        idle_exit: float = typer.Option(0.0, "--idle-exit", min=0.0,
                                        help="exit after this many seconds without clients (0 = never)"),
        verbose: bool = typer.Option(False, "--verbose", "-v", help="log every client join/leave at debug level"),
        rt_priority: int = typer.Option(0, "--rt-priority", min=0, max=99,
                                        help="SCHED_FIFO priority (0: normal scheduling; README, real-time scheduling)"),
        fault_file: Path = typer.Option(None, "--fault-file", help=(
            'line faults, re-read when the file changes: lines "CHANNEL MODE [LOSS]", MODE one of cut, babble, '
            "stuck_dominant, error_passive, intermittent (README, redundant pairs)")),
    ) -> None:
        """Run the loopback CAN hub (multi-process bus on one machine, 127.0.0.1 by default)."""
        from spacearm.base.transport.hub import run

        raise typer.Exit(run(host, port, idle_exit, verbose=verbose, rt_priority=rt_priority, fault_file=fault_file))
