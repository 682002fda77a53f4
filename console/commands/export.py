"""`spacearm export REC.mcap --csv OUT.csv`: recording to the wide CSV."""
from __future__ import annotations

import json
from pathlib import Path

import typer

from spacearm.console.errors import BadInput, friendly_errors
from spacearm.controller.recording.csv_export import export_csv
from spacearm.controller.recording.mcap_reader import RecordingError


def register(app: typer.Typer) -> None:
    @app.command()
    @friendly_errors
    def export(recording: Path = typer.Argument(..., help="An MCAP recording (complete or cut off)."),
               csv: Path = typer.Option(..., "--csv", help="Output CSV path."),
               as_json: bool = typer.Option(False, "--json", help="Print the result as JSON.")) -> None:
        """Write the recording's cycles as a wide CSV: t, q_cmd_i, q_i, dq_i, tau_i, fx..tz, ..."""
        try:
            result = export_csv(recording, csv)
        except RecordingError as exc:
            raise BadInput(str(exc), "bad_recording") from None
        if as_json:
            print(json.dumps({"csv": str(csv), "rows": result.rows, "columns": list(result.columns),
                              "complete": result.complete, "problem": result.problem,
                              "gaps": [{"t": t, "missing": n} for t, n in result.gaps]}))
            return
        print(f"{csv}: {result.rows} cycles, {len(result.columns)} columns")
        if not result.complete:
            print(f"note: recording was not closed cleanly ({result.problem}); "
                  "exported everything up to the last flushed chunk")
        for time, missing in result.gaps:
            print(f"gap: {missing} cycle(s) missing before t = {time:.3f} s")
