"""Read recordings for the diagnosis: the daemon's MCAP or the wide CSV (or anyone's CSV via a
column map), into one table of per-cycle arrays; and write the wide CSV."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from spacearm.controller.recording.csv_export import WRENCH_COLUMNS


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

    @property
    def n_joints(self) -> int:
        return self.q.shape[1]

    @property
    def dt(self) -> float:
        return float(np.median(np.diff(self.t)))

    def rows(self, sl: slice) -> "RecordingTable":
        return RecordingTable(self.t[sl], self.q_cmd[sl], self.q[sl], self.dq[sl], self.tau[sl], self.wrench[sl],
                              {k: v[sl] for k, v in self.extra.items()})


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
        table = _from_mcap(path)
        lines = [f"{path}: MCAP recording, {len(table.t)} cycles, {table.n_joints} joints"]
        if command == "measured":
            table.q_cmd = table.q.copy()
            lines.append("commanded position: the measured position (--command measured)")
        return table, lines
    from spacearm.offline.diagnosis.csv_reader import read_any_csv
    table, report = read_any_csv(path, specs, command, period)
    return table, report.lines()


def _from_mcap(path: Path) -> RecordingTable:
    from spacearm.controller.recording.mcap_reader import read_recording as read_mcap
    try:
        cycles = read_mcap(path).topic("/cycle")
        d = [m.data for m in cycles]
        arr = lambda key: np.array([row[key] for row in d], dtype=float)
        table = RecordingTable(arr("t"), arr("q_cmd"), arr("q"), arr("dq"), arr("tau"), arr("wrench")) if d else None
        if table is not None and all("sync" in row for row in d):
            # one row per SYNC: the simulated plant did not advance in the cycles the daemon skipped
            from spacearm.offline.diagnosis.time_base import sync_time_base
            from spacearm.controller.recording.csv_export import SYNC_COUNTER_MAX
            by_sync = sync_time_base(table.t, arr("sync"), SYNC_COUNTER_MAX)
            table.t = table.t if by_sync is None else by_sync
    except Exception as exc:   # any library error on a damaged file: one line, not its traceback
        raise RecordingFormatError(f"{path}: not a readable MCAP recording ({type(exc).__name__}: "
                                   f"{str(exc)[:120]})") from None
    if table is None:
        raise RecordingFormatError(f"{path}: no /cycle messages")
    if table.q.ndim != 2 or len(table.t) < 10 or np.any(np.diff(table.t) <= 0) or not all(
            np.all(np.isfinite(x)) for x in (table.t, table.q, table.q_cmd)):
        raise RecordingFormatError(f"{path}: need at least 10 cycles with increasing t and finite positions")
    return table


def write_csv(path: str | Path, table: RecordingTable) -> None:
    n = table.n_joints
    names = (["t"] + [f"q_cmd_{i}" for i in range(1, n + 1)] + [f"q_{i}" for i in range(1, n + 1)]
             + [f"dq_{i}" for i in range(1, n + 1)] + [f"tau_{i}" for i in range(1, n + 1)] + WRENCH_COLUMNS
             + sorted(table.extra))
    data = np.column_stack([table.t, table.q_cmd, table.q, table.dq, table.tau, table.wrench,
                            *[table.extra[k] for k in sorted(table.extra)]])
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.10g")
