"""Export the /cycle channel of a recording to the wide CSV other tools read.

Columns: t, q_cmd_1..n, q_1..n, dq_1..n, tau_1..n, fx, fy, fz, tx, ty, tz, then sync,
cycle, period_error, execution, dq_cmd_1..n (the velocity offset sent with q_cmd; only
for recordings that have it) and any `extra` channels (SI units). SYNC-counter gaps
are reported, never filled.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

from spacearm.controller.recording.mcap_reader import Recording, RecordingError, read_recording

WRENCH_COLUMNS = ["fx", "fy", "fz", "tx", "ty", "tz"]
SYNC_COUNTER_MAX = 240  # CiA 301 synchronous counter overflow value used on our buses


def dq_cmd_columns(n: int) -> list[str]:
    """The commanded velocity offset's columns (optional: older recordings have none)."""
    return [f"dq_cmd_{i}" for i in range(1, n + 1)]


@dataclass
class ExportResult:
    rows: int
    columns: list[str]
    gaps: list[tuple[float, int]] = field(default_factory=list)  # (time, missing cycles)
    complete: bool = True
    problem: str = ""


def find_cycle_gaps(cycles: list[int], times: list[float]) -> list[tuple[float, int]]:
    """Places where cycle numbers jump: (time after the gap, cycles missing)."""
    return [(times[i], cycles[i] - cycles[i - 1] - 1)
            for i in range(1, len(cycles)) if cycles[i] - cycles[i - 1] != 1]


def export_csv(recording_path: str | Path, csv_path: str | Path) -> ExportResult:
    recording: Recording = read_recording(recording_path)
    cycles = recording.topic("/cycle")
    if not cycles:
        raise RecordingError(f"{recording_path}: no /cycle messages to export"
                             + (f" ({recording.problem})" if recording.problem else ""))
    n = len(cycles[0].data["q"])
    extra_names = sorted({k for m in cycles for k in m.data.get("extra", {})})
    with_dq_cmd = all("dq_cmd" in m.data for m in cycles)
    columns = (["t"] + [f"q_cmd_{i}" for i in range(1, n + 1)] + [f"q_{i}" for i in range(1, n + 1)]
               + [f"dq_{i}" for i in range(1, n + 1)] + [f"tau_{i}" for i in range(1, n + 1)]
               + WRENCH_COLUMNS + ["sync", "cycle", "period_error", "execution"]
               + (dq_cmd_columns(n) if with_dq_cmd else []) + extra_names)
    with open(csv_path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(columns)
        for message in cycles:
            d = message.data
            extra = d.get("extra", {})
            writer.writerow([repr(d["t"]), *map(repr, d["q_cmd"]), *map(repr, d["q"]), *map(repr, d["dq"]),
                             *map(repr, d["tau"]), *map(repr, d["wrench"]), d["sync"], d["cycle"],
                             repr(d.get("period_error", 0.0)), repr(d.get("execution", 0.0)),
                             *(map(repr, d["dq_cmd"]) if with_dq_cmd else ()),
                             *(repr(extra[k]) if k in extra else "" for k in extra_names)])
    gaps = find_cycle_gaps([m.data["cycle"] for m in cycles], [m.data["t"] for m in cycles])
    return ExportResult(len(cycles), columns, gaps, recording.complete, recording.problem)
