"""`spacearm diagnose`: where a recording departs from the nominal simulation, and why."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import typer

from spacearm.console.errors import EXIT_USAGE, friendly_errors
from spacearm.offline.diagnosis.analysis import diagnose as run_diagnosis
from spacearm.offline.diagnosis.direct_sim import SimTraces
from spacearm.offline.diagnosis.recording_io import RecordingFormatError, parse_column_map, read_table
from spacearm.offline.diagnosis.report import write_report
from spacearm.firmware_sim.plant import load_plant_config

DEFAULT_NOMINAL = Path("configs/plant/oru_testbed_nominal.toml")


def register(app: typer.Typer) -> None:
    @app.command("diagnose")
    @friendly_errors
    def diagnose(real: Path = typer.Argument(..., help="Recording: the daemon's .mcap or the wide CSV."),
                 sim: Path = typer.Option(None, help="A simulation recording of the same commands (else replay)."),
                 replay: bool = typer.Option(True, help="Replay the commands through the nominal simulator."),
                 nominal: Path = typer.Option(DEFAULT_NOMINAL, help="Nominal plant file the simulator uses."),
                 report: Path = typer.Option(Path("diagnosis"), help="Directory for report.md, PNGs, JSON, "
                                                                     "plant_fitted.toml."),
                 columns: str = typer.Option(None, help="Column map for other files: OURS=THEIRS,... "
                                                       "(e.g. q_1=pos1,tau_1=torque1)."),
                 as_json: bool = typer.Option(False, "--json", help="Print the JSON summary.")) -> None:
        """Locate, name and fit the physics the nominal simulator leaves out; show the fit improve."""
        nominal_config = load_plant_config(nominal)
        try:
            table = read_table(real, parse_column_map(columns))
            traces = None
            if sim is not None:
                s = read_table(sim, parse_column_map(columns))
                if s.q.shape != table.q.shape:
                    raise RecordingFormatError(f"{sim}: {s.q.shape[0]} rows x {s.q.shape[1]} joints, the recording "
                                               f"has {table.q.shape[0]} x {table.q.shape[1]}")
                traces = SimTraces(s.t, s.q_cmd, s.q, s.dq, s.tau, s.wrench)
        except RecordingFormatError as exc:
            print(f"error: {exc}", file=sys.stderr)
            raise SystemExit(EXIT_USAGE) from None
        result = run_diagnosis(table, nominal_config, traces)
        data = write_report(result, report, real.name, nominal_config)
        if as_json:
            print(json.dumps(data, indent=2))
            return
        print(result.verdict)
        for c in result.channels:
            if c.significant:
                print(f"  {c.name}: held-out RMS {c.rms_before:.3g} -> {c.rms_after:.3g} "
                      f"({100 * (1 - c.rms_after / c.rms_before):.0f} % lower; noise {c.noise:.3g})")
        print(f"report: {report / 'report.md'}; fitted plant: {report / 'plant_fitted.toml'}; "
              f"{result.timings['total_s']:.1f} s")
