"""`spacearm export REC.mcap --csv OUT.csv`: recording to the wide CSV."""
from __future__ import annotations

from pathlib import Path

import typer

from spacearm.console.errors import CommandFailed, friendly_errors
from spacearm.controller.recording.csv_export import export_csv
from spacearm.controller.recording.mcap_reader import RecordingError


def register(app: typer.Typer) -> None:
    @app.command()
    @friendly_errors
    def export(recording: Path = typer.Argument(..., help="An MCAP recording (complete or cut off)."),
               csv: Path = typer.Option(..., "--csv", help="Output CSV path.")) -> None:
        """Write the recording's cycles as a wide CSV: t, q_cmd_i, q_i, dq_i, tau_i, fx..tz, ..."""
        try:
            result = export_csv(recording, csv)
        except RecordingError as exc:
            raise CommandFailed(str(exc)) from None
        print(f"{csv}: {result.rows} cycles, {len(result.columns)} columns")
        if not result.complete:
            print(f"note: recording was not closed cleanly ({result.problem}); "
                  "exported everything up to the last flushed chunk")
        for time, missing in result.gaps:
            print(f"gap: {missing} cycle(s) missing before t = {time:.3f} s")
