"""Read recordings for the diagnosis: the daemon's MCAP or the wide CSV (or anyone's CSV via a
column map), into one table of per-cycle arrays; and write the wide CSV."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from spacearm.controller.recording.csv_export import WRENCH_COLUMNS, dq_cmd_columns


class RecordingFormatError(ValueError):
    pass


@dataclass
class RecordingTable:
    t: np.ndarray
    q_cmd: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    tau: np.ndarray
    wrench: np.ndarray
    extra: dict[str, np.ndarray] = field(default_factory=dict)   # temp_i, dist, ... when present
    # rad/s (N, n): the velocity offset sent with each command, where the recording has it (the
    # daemon's since it records it); None: unknown (older recordings, other tools' CSVs)
    dq_cmd: np.ndarray | None = None

    @property
    def n_joints(self) -> int:
        return self.q.shape[1]

    @property
    def dt(self) -> float:
        return float(np.median(np.diff(self.t)))

    def rows(self, sl: slice) -> "RecordingTable":
        return RecordingTable(self.t[sl], self.q_cmd[sl], self.q[sl], self.dq[sl], self.tau[sl], self.wrench[sl],
                              {k: v[sl] for k, v in self.extra.items()},
                              None if self.dq_cmd is None else self.dq_cmd[sl])


def read_table(path: str | Path, column_map: dict[str, str] | None = None) -> RecordingTable:
    """The recording as a table (our MCAP, our CSV, or anyone's CSV with `column_map`
    OURS -> THEIR COLUMN NAME). `read_recording` takes the full `--columns` expressions."""
    from spacearm.offline.diagnosis.column_spec import ColumnSpec
    specs = [ColumnSpec(ours, theirs, text=f"{ours}={theirs}") for ours, theirs in (column_map or {}).items()]
    return read_recording(path, specs)[0]


def read_recording(path: str | Path, specs=None, command: str = "recorded", period: float | None = None):
    """(table, report lines): MCAP from the daemon, or any CSV (see csv_reader)."""
    path = Path(path)
    if not path.is_file():
        raise RecordingFormatError(f"{path}: no such file")
    if path.suffix == ".mcap":
        table, problem = _from_mcap(path)
        lines = [f"{path}: MCAP recording, {len(table.t)} cycles, {table.n_joints} joints"]
        if problem:
            # a killed writer: what the reader got back, said before anything is read from it
            lines.append(f"warning: {path.name} was not closed cleanly ({problem}): recovered {len(table.t)} "
                         f"cycles, t = {table.t[0]:.2f} - {table.t[-1]:.2f} s; whatever followed was lost")
        if table.dq_cmd is not None:
            lines.append("commanded velocity offset: recorded (dq_cmd), replayed as sent")
        if command == "measured":
            # the measured motion's own steps carry its velocity: a recorded offset on top would count it twice
            table.q_cmd, table.dq_cmd = table.q.copy(), None
            lines.append("commanded position: the measured position (--command measured)")
        return table, lines
    from spacearm.offline.diagnosis.csv_reader import read_any_csv
    table, report = read_any_csv(path, specs, command, period)
    return table, report.lines()


def _from_mcap(path: Path) -> tuple[RecordingTable, str]:
    """(the /cycle table, why reading stopped early or "" for a file closed cleanly)."""
    from spacearm.controller.recording.mcap_reader import read_recording as read_mcap
    try:
        recording = read_mcap(path, {"/cycle"})
        cycles = recording.topic("/cycle")
        d = [m.data for m in cycles]
        arr = lambda key: np.array([row[key] for row in d], dtype=float)
        table = RecordingTable(arr("t"), arr("q_cmd"), arr("q"), arr("dq"), arr("tau"), arr("wrench")) if d else None
        if table is not None and all("dq_cmd" in row for row in d):     # recorded since the daemon sends it
            table.dq_cmd = arr("dq_cmd")
        if table is not None and all("sync" in row for row in d):
            # one row per SYNC: the simulated plant did not advance in the cycles the daemon skipped
            from spacearm.offline.diagnosis.time_base import sync_time_base
            from spacearm.controller.recording.csv_export import SYNC_COUNTER_MAX
            by_sync = sync_time_base(table.t, arr("sync"), SYNC_COUNTER_MAX)
            table.t = table.t if by_sync is None else by_sync
        if table is not None and table.dq_cmd is not None and table.dq_cmd.shape != table.q_cmd.shape:
            raise ValueError(f"dq_cmd has shape {table.dq_cmd.shape}, q_cmd {table.q_cmd.shape}")
    except Exception as exc:   # any library error on a damaged file: one line, not its traceback
        raise RecordingFormatError(f"{path}: not a readable MCAP recording ({type(exc).__name__}: "
                                   f"{str(exc)[:120]})") from None
    if table is None:
        raise RecordingFormatError(f"{path}: no /cycle messages")
    if table.q.ndim != 2 or len(table.t) < 10 or np.any(np.diff(table.t) <= 0) or not all(
            np.all(np.isfinite(x)) for x in (table.t, table.q, table.q_cmd)):
        raise RecordingFormatError(f"{path}: need at least 10 cycles with increasing t and finite positions")
    return table, "" if recording.complete else recording.problem


def write_csv(path: str | Path, table: RecordingTable) -> None:
    n = table.n_joints
    names = (["t"] + [f"q_cmd_{i}" for i in range(1, n + 1)] + [f"q_{i}" for i in range(1, n + 1)]
             + [f"dq_{i}" for i in range(1, n + 1)] + [f"tau_{i}" for i in range(1, n + 1)] + WRENCH_COLUMNS
             + (dq_cmd_columns(n) if table.dq_cmd is not None else []) + sorted(table.extra))
    data = np.column_stack([table.t, table.q_cmd, table.q, table.dq, table.tau, table.wrench,
                            *([] if table.dq_cmd is None else [table.dq_cmd]),
                            *[table.extra[k] for k in sorted(table.extra)]])
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.10g")
