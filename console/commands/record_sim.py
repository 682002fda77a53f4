"""`spacearm record-sim`: a commanded trajectory through controller and simulator in lockstep."""
from __future__ import annotations

import sys
from pathlib import Path

import typer

from spacearm.console.errors import EXIT_USAGE, BadInput, CommandFailed, friendly_errors
from spacearm.base.config.arm import load_arm_config
from spacearm.offline.diagnosis.direct_sim import on_arm_drives
from spacearm.offline.diagnosis.record import DEFAULT_ARM, RecordSimError, record_can, record_direct
from spacearm.offline.diagnosis.trajectory import TrajectoryError, load_trajectory
from spacearm.base.config.bus import DEFAULT_BUS_CONFIG
from spacearm.drivers.errors import DriverError
from spacearm.firmware_sim.plant import load_plant_config


def register(app: typer.Typer) -> None:
    @app.command("record-sim")
    @friendly_errors
    def record_sim(plant: Path = typer.Option(..., help="Plant file (the hidden truth)."),
                   trajectory: Path = typer.Option(..., help="CSV with t, q_cmd_1..n (rad)."),
                   out: Path = typer.Option(..., help="REC.mcap or REC.csv (wide CSV)."),
                   arm: Path = typer.Option(DEFAULT_ARM, help="Arm file."),
                   bus_config: Path = typer.Option(DEFAULT_BUS_CONFIG, help="Bus file."),
                   direct: bool = typer.Option(False, help="Direct simulation path (no CAN; CSV only, fast).")) -> None:
        """Run TRAJECTORY on the simulated PLANT through the daemon over CAN (lockstep) and record it."""
        config = load_plant_config(plant)
        if out.suffix not in (".mcap", ".csv"):
            print(f"error: --out {out}: must end in .mcap or .csv", file=sys.stderr)
            raise SystemExit(EXIT_USAGE)
        try:
            traj = load_trajectory(trajectory, n_joints=len(load_arm_config(arm).joints))
        except TrajectoryError as exc:
            print(f"error: {exc}", file=sys.stderr)
            raise SystemExit(EXIT_USAGE) from None
        try:
            if direct:
                if out.suffix != ".csv":
                    raise BadInput("--direct writes the wide CSV only")
                # the arm's drives, as the daemon configures them at bring-up on the CAN path
                table = record_direct(on_arm_drives(config, arm, bus_config), traj, out, hold_cycles=0)
                rows = len(table.t)
            else:
                record_can(config, traj, out, arm, bus_config)
                rows = None
        except (RecordSimError, DriverError) as exc:
            raise CommandFailed(str(exc)) from None
        path = "direct simulation" if direct else "controller + simulator over CAN (lockstep)"
        print(f"recorded {traj.duration:.1f} s of {trajectory.name} via {path} -> {out}"
              + (f" ({rows} cycles)" if rows else ""))
