"""Read recordings for the diagnosis: the daemon's MCAP or the wide CSV (or anyone's CSV via a
column map), into one table of per-cycle arrays; and write the wide CSV."""
from __future__ import annotations

import csv
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


def parse_column_map(text: str | None) -> dict[str, str]:
    """'q_1=pos_a,tau_1=trq_a' -> {'q_1': 'pos_a', ...} (our name = their column)."""
    if not text:
        return {}
    out = {}
    for item in text.split(","):
        if "=" not in item:
            raise RecordingFormatError(f"column map entry {item!r}: expected OURS=THEIRS")
        ours, theirs = (s.strip() for s in item.split("=", 1))
        out[ours] = theirs
    return out


def read_table(path: str | Path, column_map: dict[str, str] | None = None) -> RecordingTable:
    path = Path(path)
    if not path.exists():
        raise RecordingFormatError(f"{path}: no such file")
    if path.suffix == ".mcap":
        return _from_mcap(path)
    return _from_csv(path, column_map or {})


def _from_mcap(path: Path) -> RecordingTable:
    from spacearm.controller.recording.mcap_reader import read_recording
    cycles = read_recording(path).topic("/cycle")
    if not cycles:
        raise RecordingFormatError(f"{path}: no /cycle messages")
    d = [m.data for m in cycles]
    arr = lambda key: np.array([row[key] for row in d], dtype=float)
    return RecordingTable(arr("t"), arr("q_cmd"), arr("q"), arr("dq"), arr("tau"), arr("wrench"))


def _from_csv(path: Path, column_map: dict[str, str]) -> RecordingTable:
    with open(path, newline="") as handle:
        reader = csv.reader(handle)
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise RecordingFormatError(f"{path}: empty file") from None
        rows = [r for r in reader if r]
    index = {name: i for i, name in enumerate(header)}
    for ours, theirs in column_map.items():
        if theirs not in index:
            raise RecordingFormatError(f"{path}: column map names {theirs!r}, not a column of the file")
        index[ours] = index[theirs]
    n = sum(1 for name in index if name.startswith("q_cmd_"))
    if "t" not in index or n == 0:
        raise RecordingFormatError(f"{path}: need columns t and q_cmd_1..n (use --columns OURS=THEIRS to map)")

    def col(name: str, required: bool = True) -> np.ndarray:
        if name not in index:
            if required:
                raise RecordingFormatError(f"{path}: missing column {name!r} (use --columns {name}=THEIRS)")
            return np.zeros(len(rows))
        try:
            return np.array([float(r[index[name]]) if r[index[name]] != "" else np.nan for r in rows])
        except (ValueError, IndexError) as exc:
            raise RecordingFormatError(f"{path}: column {name!r}: {exc}") from None

    joints = lambda prefix, req=True: np.column_stack([col(f"{prefix}_{i}", req) for i in range(1, n + 1)])
    extra = {name: col(name) for name in index if name.startswith("temp") or name in ("dist",)}
    table = RecordingTable(col("t"), joints("q_cmd"), joints("q"), joints("dq", False), joints("tau", False),
                           np.column_stack([col(c, False) for c in WRENCH_COLUMNS]), extra)
    if len(table.t) < 10 or np.any(np.diff(table.t) <= 0):
        raise RecordingFormatError(f"{path}: need at least 10 rows with increasing t")
    return table


def write_csv(path: str | Path, table: RecordingTable) -> None:
    n = table.n_joints
    names = (["t"] + [f"q_cmd_{i}" for i in range(1, n + 1)] + [f"q_{i}" for i in range(1, n + 1)]
             + [f"dq_{i}" for i in range(1, n + 1)] + [f"tau_{i}" for i in range(1, n + 1)] + WRENCH_COLUMNS
             + sorted(table.extra))
    data = np.column_stack([table.t, table.q_cmd, table.q, table.dq, table.tau, table.wrench,
                            *[table.extra[k] for k in sorted(table.extra)]])
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.10g")
