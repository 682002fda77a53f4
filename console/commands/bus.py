"""`spacearm bus scan BUS`: the nodes on a CAN bus, compared with a bus file, as a bus file.

    spacearm bus scan socketcan:can0 [--bus-file configs/bus/arm.toml] [--write found.toml] [--json]

    spacearm bus fault FILE LINE MODE [--loss P]

`fault` sets LINE's entry in a line-fault file that `spacearm sim --fault-file FILE` or
`spacearm hub --fault-file FILE` re-reads at once (LINE: A, B or a line's name for the
simulator, a channel name for the hub; MODE cut, babble, stuck_dominant, error_passive,
intermittent, ok = restore; base/transport/line_faults.py).

BUS is a bus spec (virtual:NAME, loopback:NAME, socketcan:CHANNEL). The scan is an SDO upload of
1000h/1018h to node-IDs 1-127 (no NMT command); with --bus-file each node is compared with its
entry and EDS (identity, objects the device lacks, read-only where the EDS says writable: the
objects bring-up writes get their own value written back). Exit 1 when there are differences.
"""
from __future__ import annotations

import json
from pathlib import Path

import typer

from spacearm.console.errors import friendly_errors


def register(app: typer.Typer) -> None:
    bus_app = typer.Typer(help="Look at a CAN bus: which CANopen nodes are on it.", no_args_is_help=True)

    @bus_app.command("fault")
    def fault(file: Path = typer.Argument(..., help="the fault file the simulator or hub was started with"),
              line: str = typer.Argument(..., help="A, B or a line's name (arm-a, vcan1; the hub: its channel)"),
              mode: str = typer.Argument(..., help="cut, babble, stuck_dominant, error_passive, intermittent, ok"),
              loss: float | None = typer.Option(None, "--loss", help="loss probability 0..1 (intermittent, "
                                                                     "error_passive)")) -> None:
        """Cut, disturb or restore one line of a redundant pair at run time (a simulator's or hub's fault file)."""
        from spacearm.base.transport.line_faults import LineFaultError, write_fault_entry

        try:
            write_fault_entry(file, line, mode, loss)
        except (LineFaultError, OSError) as exc:
            typer.echo(f"error[bad_argument]: bus fault: {exc}", err=True)
            raise typer.Exit(2)
        typer.echo(f"line {line}: {mode}" + (f" (loss {loss:g})" if loss is not None else "") + f" in {file}")

    @bus_app.command("scan")
    @friendly_errors
    def scan(bus: str = typer.Argument(..., help="bus spec: virtual:NAME, loopback:NAME, socketcan:CHANNEL"),
             bus_file: Path | None = typer.Option(None, "--bus-file", help="compare with this bus file and its EDS"),
             write: Path | None = typer.Option(None, "--write", help="write a starting bus file for what was found"),
             timeout: float = typer.Option(0.2, "--timeout", min=0.01, max=5.0, help="s to wait for each round of answers"),
             as_json: bool = typer.Option(False, "--json", help="one JSON object")) -> None:
        """Find the nodes (node-IDs 1-127), report device type and identity, compare, write a bus file."""
        import time

        from spacearm.base.config.bus import load_bus_config
        from spacearm.drivers import bus_scan

        config = load_bus_config(bus_file) if bus_file is not None else None
        t0 = time.monotonic()
        found = bus_scan.scan(bus, timeout=timeout)
        seconds = time.monotonic() - t0
        differences = bus_scan.compare(found, config, bus) if config is not None else []
        if write is not None:
            write.write_text(bus_scan.starting_bus_file(found, config))
        if as_json:
            print(json.dumps({"bus": bus, "seconds": round(seconds, 3),
                              "nodes": [{"node_id": n.node_id, "device_type": n.device_type,
                                         "identity": {str(k): v for k, v in n.identity.items()}} for n in found],
                              "differences": differences, "written": str(write) if write else None}))
        else:
            print(f"{len(found)} node(s) on {bus} (node-IDs 1-127 scanned in {seconds:.2f} s)")
            for node in found:
                print(f"  {node.describe()}")
            if config is not None:
                print(f"compared with {bus_file}: " + (f"{len(differences)} difference(s)" if differences else "matches"))
                for line in differences:
                    print(f"  {line}")
            if write is not None:
                print(f"starting bus file written: {write}")
        if differences:
            raise typer.Exit(1)

    app.add_typer(bus_app, name="bus")
